from setuptools import find_packages, setup

package_name = "sim_plant_node"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/sim_plant.yaml", "config/list_case1.yaml",
                                               "config/list_case2.yaml", "config/list_case3.yaml",
                                               "config/list_case4.yaml"]),
        ("share/" + package_name + "/config", ["config/delay_loop.yaml", "config/qft_ffb.yaml",
                                               "config/fastdds_writers.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="Vibration suppression maintainers",
    maintainer_email="maintainers@vibration-suppression.dev",
    description="Simulated plants and the demo of the vibration-suppression suite",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "sim_plant = sim_plant_node.node.sim_plant:main",
            "demo = sim_plant_node.clients.demo:main",
        ],
    },
)
