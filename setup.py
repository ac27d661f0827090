"""ament_python build for manip_kin (colcon, ``pip install``)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "manip_kin"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    # The C++ backends are compiled where they run (manip_kin/codegen/native.py), from their source.
    package_data={PACKAGE: ["collision/*.cpp"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.json")),
        (f"share/{PACKAGE}/config/robots", glob("config/robots/*")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,  # narrow_phase.cpp is compiled from the installed file
    maintainer="manip_kin developers",
    maintainer_email="dev@manip-kin.invalid",
    description="Kinematic control of serial manipulators for ROS 2 Jazzy.",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            # manip_kin.entry: each imports its module's main, ending quietly on a Ctrl-C meanwhile.
            "manip_kin = manip_kin.entry:manip_kin",
            "robot_state = manip_kin.entry:robot_state",
            "cartesian_controller = manip_kin.entry:cartesian_controller",
            "trajectory_generator = manip_kin.entry:trajectory_generator",
            "recorder = manip_kin.entry:recorder",
            "live_view = manip_kin.entry:live_view",
        ],
    },
)
