from setuptools import find_packages, setup

package_name = "arm_benchmarks"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="ARM ROS maintainers",
    maintainer_email="maintainers@arm-ros.dev",
    description=open("package.xml").read().split("<description>")[1].split("</description>")[0],
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "bench_perf = arm_benchmarks.bench_perf:main",
            "bench_seg = arm_benchmarks.bench_seg:main",
            "make_shape_set = arm_benchmarks.shape_set:main",
            "bench_recon = arm_benchmarks.bench_recon:main",
            "bench_manip = arm_benchmarks.bench_manip:main",
            "bench_manip_pool = arm_benchmarks.manip_pool:main",
            "bench_robustness = arm_benchmarks.bench_robustness:main",
            "bench_camera_pose = arm_benchmarks.bench_camera_pose:main",
            "bench_real = arm_benchmarks.bench_real:main",
            "bench_demo = arm_benchmarks.bench_demo:main",
            "bench_pushability = arm_benchmarks.pushability:main",
            "bench_behaviours = arm_benchmarks.bench_behaviours:main",
        ]
    },
)
