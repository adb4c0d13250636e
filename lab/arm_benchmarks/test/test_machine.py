from arm_benchmarks.machine import cpu_model, machine_description


def test_cpu_model_reads_the_model_name_line():
    text = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD  EPYC 7B13\nflags\t\t: fpu\n"
    assert cpu_model(text) == "AMD EPYC 7B13"


def test_cpu_model_without_a_model_line_falls_back_to_the_platform():
    assert cpu_model("processor : 0\n")


def test_machine_description_names_cores_and_python():
    text = machine_description()
    assert "cores" in text and "python" in text
