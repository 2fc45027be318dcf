"""Registers ``DV2S-v0`` with Gymnasium as soon as Gymnasium is imported.

Installed with a one-line ``.pth`` file so that ``gym.make("DV2S-v0")`` works after
``pip install dv2s-gym`` with no ``import dv2s_gym``. It costs nothing at start-up:
it only adds an import hook that waits for ``gymnasium``.
"""

import importlib.util
import sys


class _GymnasiumImportHook:
    """Meta-path finder that runs ``register_envs()`` right after ``gymnasium`` loads."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname != "gymnasium":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec("gymnasium")
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def exec_and_register(module):
            exec_module(module)
            try:
                from envs.registration import register_envs

                register_envs()
            except Exception:  # never break an unrelated `import gymnasium`
                pass

        spec.loader.exec_module = exec_and_register
        return spec


def install() -> None:
    """Add the hook (or register at once if Gymnasium is already imported)."""
    if "gymnasium" in sys.modules:
        try:
            from envs.registration import register_envs

            register_envs()
        except Exception:
            pass
    elif not any(isinstance(f, _GymnasiumImportHook) for f in sys.meta_path):
        sys.meta_path.insert(0, _GymnasiumImportHook())
