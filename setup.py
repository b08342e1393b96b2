from glob import glob
from pathlib import Path

from setuptools import Extension, find_packages, setup

package_name = "biped_sim"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "benchmarks.*"]),
    # the shipped robot descriptions (biped_sim/config/models.py)
    package_data={"biped_sim.config": ["robots/*.yaml", "robots/*.urdf"],
                  # the compiled kernels' runtime and table: model_kernels compiles a user's robot's twin with
                  # the installed package's folder on the include path
                  "biped_sim.engine": ["_kernel_table.h", "_kernels_runtime.h"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/msg_configs", glob("msg_configs/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    # the compiled twin of the generated code (biped_sim/engine/compiled.py): optional, so that a machine
    # without a C compiler still installs and runs the same code in Python, several times slower;
    # no floating-point contraction, so that its results are the Python code's bits
    # and the compiled hybrid loop (biped_sim/engine/compiled_loop.py) on the same generated code's kernels
    ext_modules=[Extension("biped_sim.engine._gen._cmodel", ["biped_sim/engine/_gen/_cmodel.c"],
                           extra_compile_args=["-O2", "-ffp-contract=off"], optional=True),
                 # (it includes the hybrid loop's rules, biped_sim/engine/loop_rules.py compiled by Cython into the
                 # committed _loop_rules.c by tools/generate_loop.py: built with gcc alone)
                 Extension("biped_sim.engine._core", ["biped_sim/engine/_core.c"],
                           depends=["biped_sim/engine/_gen/_kernels.h", "biped_sim/engine/_loop_state.h",
                                    "biped_sim/engine/_loop_rules.c", "biped_sim/engine/_kernel_table.h",
                                    "biped_sim/engine/_loop_table.h", "biped_sim/engine/_py_doubles.h"],
                           # the rules are Cython's public (exported) functions: without semantic interposition
                           # gcc may inline the small ones into the loop as it does a static function
                           extra_compile_args=["-O2", "-ffp-contract=off", "-fno-semantic-interposition"],
                           optional=True),
                 # the variational terms of the three-link's DOP853 steps (biped_sim/engine/variational.py)
                 # (-O3: gcc vectorises its small matrix loops, 0.9 -> 0.6 us a stage; no reassociation, no contraction)
                 Extension("biped_sim.engine._variational", ["biped_sim/engine/_variational.c"],
                           depends=["biped_sim/engine/_gen/_kernels.h", "biped_sim/engine/_gen/_derivatives.h",
                                    "biped_sim/engine/_stance_derivative.h", "biped_sim/engine/_py_doubles.h"],
                           extra_compile_args=["-O3", "-ffp-contract=off"], optional=True),
                 # the walking laws as compiled torque laws of the loop's hook (biped_sim/control/walking.py),
                 # and their derivatives
                 Extension("biped_sim.control._laws", ["biped_sim/control/_laws.c"],
                           depends=["biped_sim/engine/_gen/_kernels.h", "biped_sim/engine/_gen/_derivatives.h",
                                    "biped_sim/engine/_stance_derivative.h"],
                           extra_compile_args=["-O2", "-ffp-contract=off"], optional=True),
                 # the recorder's frame buffer (biped_sim/recording/frames.py: its Python twin is the fallback)
                 Extension("biped_sim.recording._frames", ["biped_sim/recording/_frames.c"],
                           extra_compile_args=["-O2"], optional=True)]
    # the shipped robots' compiled kernels (biped_sim/engine/model_kernels.py, written by make generate): each
    # source is its robot's part and includes the runtime every robot shares (_kernels_runtime.h);
    # without them those robots run their dynamics in Python (numpy)
    + [Extension(f"biped_sim.engine._gen.models.{Path(c).stem}", [c], include_dirs=["biped_sim/engine"],
                 depends=["biped_sim/engine/_kernels_runtime.h", "biped_sim/engine/_kernel_table.h"],
                 extra_compile_args=["-O2", "-ffp-contract=off"], optional=True)
       for c in sorted(glob("biped_sim/engine/_gen/models/_kernels_*.c"))],
    # every third-party import of the installed package; ROS packages (rclpy, the message packages,
    # ament_index_python) come from a ROS installation and are declared in package.xml instead
    # zstandard and lz4 (chunk compression of the bag writer, recording/mcapfile.py) come with mcap;
    # named here since the writer imports them itself
    install_requires=["numpy", "scipy", "PyYAML", "mcap", "zstandard", "lz4", "tqdm"],
    extras_require={
        # imported only where a figure is drawn (biped-sim inspect, biped-sim accuracy, biped-sim animate)
        "plot": ["matplotlib", "pillow"],
        # MP4 output of biped-sim animate (its wheel bundles an ffmpeg binary: not installed by default)
        "video": ["imageio-ffmpeg"],
        # backend="ray" of biped_sim.sweep / biped-sim sweep --backend ray (biped_sim/analysis/sweep.py)
        "ray": ["ray"],
        # RecordedRun.to_dataframe of biped_sim.load_run (biped_sim/recording/loaded_run.py)
        "pandas": ["pandas"],
        # torque laws written in Python run compiled in the loop (biped_sim/control/compiled_laws.py): numba
        # and llvmlite, about 210 MB installed; without them such a law runs as plain Python (docs/controllers.md)
        "numba": ["numba"],
        # a user's robot description generated on first use (biped_sim/config/codegen.py; docs/models.md)
        "models": ["sympy"],
    },
    # the test environment (pytest, the independent bag readers, colcon, ruff, Ray) is pinned in requirements-dev.txt
    zip_safe=True,
    maintainer="biped_sim team",
    maintainer_email="biped_sim@example.com",
    description="Exact hybrid-dynamics simulator of a planar three-link biped, as an rclpy node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "biped-sim = biped_sim.cli:main",
            "sim_node = biped_sim.ros:sim_node",
            "torque_pub = biped_sim.ros:torque_pub",
            "biped_echo = biped_sim.ros:biped_echo",
            "walk_controller = biped_sim.ros:walk_controller",
        ],
    },
)
