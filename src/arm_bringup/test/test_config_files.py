"""The node parameter files in config/ are the config dataclasses' parameters, and few."""

import pathlib

from arm_bringup.camera_presets import load_preset
from arm_bringup.config_files import NODE_CONFIGS, main, parameter_names, rendered_files

CONFIG = pathlib.Path(__file__).resolve().parents[1] / "config"


def test_each_parameter_file_is_its_dataclass_rendered():
    for name, text in rendered_files().items():
        assert (CONFIG / name).read_text() == text, f"config/{name}: run python -m arm_bringup.config_files config/"
    assert main([str(CONFIG), "--check"]) == 0


def test_each_node_declares_at_most_15_parameters_with_unique_names():
    for key in NODE_CONFIGS:
        names = parameter_names(key)
        assert 0 < len(names) <= 15 and len(set(names)) == len(names), (key, names)


def test_every_shipped_camera_preset_sets_only_parameters_its_nodes_declare():
    for preset in sorted((CONFIG / "cameras").glob("*.yaml")):
        loaded = load_preset(str(preset))
        for key, values in loaded["parameters"].items():
            assert set(values) <= set(parameter_names(key)), preset.name


def test_a_preset_setting_an_unknown_parameter_is_refused(tmp_path):
    import pytest

    from arm_bringup.camera_presets import PresetError

    text = (CONFIG / "cameras" / "realsense_d4xx.yaml").read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("sync_tolerance_s:", "workspace_min_m: [0, 0, 0]\n      sync_tolerance_s:"))
    with pytest.raises(PresetError, match="workspace_min_m"):
        load_preset(str(bad))
