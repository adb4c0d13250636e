"""Every import of a package's code is declared in its package.xml, so that
`rosdep install --from-paths src` installs what the package needs: workspace and ROS packages by their
names, third-party Python modules by their rosdep keys (those not in rosdistro's own rosdep database
are defined in rosdep.yaml at the repository root)."""

import ast
import pathlib
import sys
import xml.etree.ElementTree as ET

import pytest
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[1]
PRODUCT = sorted(p.parent for p in (ROOT / "src").glob("*/package.xml") if (p.parent / "setup.py").is_file())
LAB = sorted(p.parent for p in (ROOT / "lab").glob("*/package.xml") if (p.parent / "setup.py").is_file())
PACKAGES = PRODUCT + LAB
ROSDEP_KEYS = {  # Python module -> rosdep key
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "cv2": "python3-opencv",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "mpl_toolkits": "python3-matplotlib",
    "tqdm": "python3-tqdm",
    "skimage": "python3-skimage",
    "torch": "python3-torch",
    "trimesh": "python3-trimesh-pip",
    "mujoco": "python3-mujoco-pip",
    "coacd": "python3-coacd-pip",
    "manifold3d": "python3-manifold3d-pip",
    "rosbags": "python3-rosbags-pip",
    "setuptools": "python3-setuptools",
    "pytest": "python3-pytest",
}
LOCAL_KEYS = ("python3-trimesh-pip", "python3-mujoco-pip", "python3-coacd-pip", "python3-manifold3d-pip",
              "python3-rosbags-pip")  # fmt: skip


def imported_modules(package: pathlib.Path, with_tests: bool = False) -> set[str]:
    """Top-level modules imported by the package's code (its Python package and launch files, and
    with_tests its tests)."""
    modules = set()
    left_out = ("setup.py",) if with_tests else ("test", "setup.py")
    files = [f for f in package.rglob("*.py") if f.relative_to(package).parts[0] not in left_out]
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                modules |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split(".")[0])
    return modules - set(sys.stdlib_module_names) - {package.name}


def declared(package: pathlib.Path) -> set[str]:
    root = ET.parse(package / "package.xml").getroot()
    tags = ("depend", "exec_depend", "build_depend", "buildtool_depend")
    return {element.text.strip() for tag in tags for element in root.findall(tag)}


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.name)
def test_every_import_is_declared(package):
    needed = {ROSDEP_KEYS.get(module, module) for module in imported_modules(package)}
    unknown = {m for m in needed if m not in ROSDEP_KEYS.values() and not _is_ros_package(m)}
    assert not unknown, f"{package.name} imports modules with no rosdep key here: {sorted(unknown)}"
    missing = needed - declared(package)
    assert not missing, f"{package.name}/package.xml does not declare {sorted(missing)}"


def test_keys_outside_rosdistro_are_defined_in_the_repository():
    rules = yaml.safe_load((ROOT / "rosdep.yaml").read_text())
    used = set().union(*(declared(p) for p in PACKAGES))
    assert {k for k in used if k.endswith("-pip")} <= set(rules), "each -pip key needs a rule in rosdep.yaml"
    for key in LOCAL_KEYS:
        assert rules[key]["debian"]["pip"]["packages"] and rules[key]["ubuntu"]["pip"]["packages"]


def _is_ros_package(name: str) -> bool:
    """Workspace packages and ROS packages (message packages, rclpy, launch, ament_index_python, tf2_ros)."""
    return (
        name.startswith("arm_")
        or name.endswith(("_msgs", "_srvs", "_interfaces"))
        or name in {"rclpy", "launch", "launch_ros", "ament_index_python", "rosidl_runtime_py", "tf2_ros"}
    )


LAB_PACKAGES = {p.name for p in LAB}  # lab/: benchmarks, robustness harness, data generation and training


def test_the_lab_is_what_lab_holds():
    assert LAB_PACKAGES == {"arm_benchmarks", "arm_training"}


@pytest.mark.parametrize("package", PRODUCT, ids=lambda p: p.name)
def test_no_product_package_imports_the_lab(package):
    """Neither a product package's code nor its tests import a lab package."""
    lab = imported_modules(package, with_tests=True) & LAB_PACKAGES
    assert not lab, f"{package.name} imports {sorted(lab)}"
