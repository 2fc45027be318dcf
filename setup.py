"""Build hook: ship ``dv2s_gym_autoregister.pth`` at the top of site-packages.

All metadata lives in pyproject.toml; this only adds the .pth file (which makes
``gym.make("DV2S-v0")`` work after installation without importing dv2s_gym).
"""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

PTH = "dv2s_gym_autoregister.pth"


class BuildPyWithPth(build_py):
    def run(self):
        super().run()
        self.copy_file(PTH, str(Path(self.build_lib) / PTH), preserve_mode=0)

    def get_outputs(self, include_bytecode=1):
        return super().get_outputs(include_bytecode) + [str(Path(self.build_lib) / PTH)]


setup(cmdclass={"build_py": BuildPyWithPth})
