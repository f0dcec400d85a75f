from glob import glob

from setuptools import find_packages, setup

package_name = "kite_rto"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        # parameter defaults, the Fast DDS profile the nodes load (kite_rto/nodes/dds_profile.py), viewer layouts
        ("share/" + package_name + "/config",
         glob("config/*.yaml") + glob("config/*.xml") + glob("config/*.foxglove.json")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="kite_rto developers",
    maintainer_email="kite_rto@example.com",
    description="Real-time optimization of a crosswind power kite (GMA) as ROS 2 nodes",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "plant = kite_rto.executables:plant",
            "echo_pilot = kite_rto.executables:echo_pilot",
            "controller = kite_rto.executables:controller",
            "optimizer = kite_rto.executables:optimizer",
            # operator tools (kite_ prefix: no clash with shell commands such as echo in a venv's bin/)
            "kite_monitor = kite_rto.tools.monitor:main",
            "kite_echo = kite_rto.tools.echo:main",
            "kite_ctl = kite_rto.tools.kite_ctl:main",
            "kite_record = kite_rto.executables:kite_record",
            "kite_report = kite_rto.tools.rto_report:main",
            "kite_demo = kite_rto.tools.demo:main",
            "kite_viz = kite_rto.executables:kite_viz",
            "kite_foxglove = kite_rto.executables:kite_foxglove",
            "kite_campaign = kite_rto.tools.campaign:main",
        ],
    },
)
