from setuptools import find_packages, setup

package_name = "arm_segmentation"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["checkpoints/*"]},
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="ARM ROS maintainers",
    maintainer_email="maintainers@arm-ros.dev",
    description=open("package.xml").read().split("<description>")[1].split("</description>")[0],
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "segmentation_node = arm_segmentation.segmentation_node:main",
        ]
    },
)
