from setuptools import find_packages, setup

package_name = "shaper_nodes"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/shaper.yaml", "config/identifier.yaml", "config/learner.yaml",
                                           "config/mrilc.yaml"]),
        ("share/" + package_name + "/config", ["config/scheduler.yaml", "config/calibrate.yaml",
                                           "config/calibrate_quick.yaml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="Vibration suppression maintainers",
    maintainer_email="maintainers@vibration-suppression.dev",
    description="Input shaping core and ROS 2 nodes",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "shaper_node = shaper_nodes.nodes.shaper:main",
            "recorder = shaper_nodes.nodes.recorder:main",
            "identifier = shaper_nodes.nodes.identifier:main",
            "learner = shaper_nodes.nodes.learner:main",
            "scheduler = shaper_nodes.nodes.scheduler:main",
            "calibrate = shaper_nodes.nodes.calibrate:main",
            "list_replay = shaper_nodes.cli.list_replay:main",
            "shaper_design = shaper_nodes.cli.shaper_design:main",
            "loop_design = shaper_nodes.cli.loop_design:main",
            "analyze_bag = shaper_nodes.cli.analyze_bag:main",
            "analyze_fleet = shaper_nodes.cli.analyze_fleet:main",
            "bag_play = shaper_nodes.nodes.bag_play:main",
            "shaper_keystore = shaper_nodes.cli.keystore:main",
            "send_goal = shaper_nodes.cli.send_goal:main",
        ],
    },
)
