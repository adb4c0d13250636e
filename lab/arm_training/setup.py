from setuptools import find_packages, setup

package_name = "arm_training"

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
            "datagen = arm_training.reconstruction.datagen:main",
            "train = arm_training.reconstruction.train:main",
            "seg_datagen = arm_training.segmentation.boundary_data:main",
            "seg_train = arm_training.segmentation.boundary_train:main",
            "seg_merge_train = arm_training.segmentation.merge_train:main",
            "seg_outline_train = arm_training.segmentation.outline_train:main",
        ]
    },
)
