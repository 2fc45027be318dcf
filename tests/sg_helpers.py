"""Helpers of the rules-SG composition tests: generate from a hand-built parse, run a script."""

from dv2s_gym.pipeline.semantics.parsed import ParsedDescription
from dv2s_gym.pipeline.sg.rules import generate as sg_generate


def generate_from(monkeypatch, parsed: ParsedDescription, seed: int = 0):
    """``generate_rules`` on ``parsed`` as if the parser had read its text so."""
    monkeypatch.setattr(sg_generate, "parse_description", lambda text: parsed)
    return sg_generate.generate_rules(parsed.text, seed=seed)


def run_script(script, seconds: float, seed: int = 0):
    """The trace of one episode of ``script`` with the script's ego driving, ``seconds`` long."""
    from envs.dv2s_env import DV2SEnv

    env = DV2SEnv(scenario=script, config={"duration": seconds, "ego_policy": "scenic"})
    try:
        env.reset(seed=seed)
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(1)
            done = terminated or truncated
        return env.unwrapped.trace
    finally:
        env.close()


def trace_actions(script, who: str, seeds=range(3), seconds: float = 8.0):
    """Per seed, the actions the trace of ``script`` shows for participant type ``who``."""
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace

    return [{a for k, a in elements_from_trace(run_script(script, seconds, seed)).actions if k == who}
            for seed in seeds]
