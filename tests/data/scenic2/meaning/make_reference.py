"""Record what Scenic 2.1.0 does with each case in ``cases.json`` (run under Scenic 2, not by the tests).

Usage, from a Python 3.11 virtualenv holding ``pip install scenic==2.1.0`` (the project's venv holds 3.1.1)::

    python tests/data/scenic2/meaning/make_reference.py

It compiles every case's Scenic 2 ``source`` with Scenic 2.1.0, samples one scene (the cases are
deterministic: no random values, or only ones the recorded fields do not depend on), records each
object's x, y, heading (degrees), width, length and mutationScale, and for cases with ``simulate``
runs Scenic 2's DummySimulator for at most 200 steps and records the final ``currentTime`` (steps);
it writes them into ``reference.json`` next to this file. For the real script
``iccv_2_agent_scenario.scenic`` (``Car ahead of ego by Range(3, 5)``) it samples 20 scenes and records
where the second car is in ego's frame: its lateral offset and its longitudinal offset minus half its
length (Scenic 2 measured ``by`` from ego's centre, so the latter lies in [3, 5]). ``tests/test_scenic2_meaning.py`` upgrades
each source to Scenic 3 and checks that Scenic 3.1.1 reproduces these values.
"""

import json
import math
from pathlib import Path

import scenic
from scenic.core.simulators import DummySimulator

HERE = Path(__file__).resolve().parent


def objects_of(scene):
    return [{"x": round(float(o.position.x), 6), "y": round(float(o.position.y), 6),
             "heading": round(math.degrees(float(o.heading)) % 360, 6), "width": float(o.width),
             "length": float(o.length), "mutationScale": float(o.mutationScale)} for o in scene.objects]


def main():
    cases = json.loads((HERE / "cases.json").read_text())
    out = {"scenic": scenic.__version__ if hasattr(scenic, "__version__") else "2.1.0", "cases": {}}
    for name, case in cases.items():
        params = {"map": str(HERE.parents[1] / "maps" / "CARLA" / "Town01.xodr")} if case.get("map") else {}
        scenario = scenic.scenarioFromString(case["source"], params=params)
        scene, _ = scenario.generate(maxIterations=1)
        record = {"objects": objects_of(scene)}
        if case.get("simulate"):
            simulation = DummySimulator(timestep=0.1).simulate(scene, maxSteps=200, maxIterations=1)
            record["steps"] = simulation.currentTime
        out["cases"][name] = record
        print(name, record)
    import random

    import numpy

    script = (HERE.parent / "iccv_2_agent_scenario.scenic").read_text()
    params = {"map": str(HERE.parents[1] / "maps" / "CARLA" / "Town01.xodr")}
    scenario = scenic.scenarioFromString(script, params=params)
    offsets = []
    for seed in range(20):
        random.seed(seed)
        numpy.random.seed(seed)
        scene, _ = scenario.generate(maxIterations=2000)
        ego, car = scene.objects[0], scene.objects[1]
        local = (car.position - ego.position).rotatedBy(-ego.heading)
        offsets.append([round(float(local.x), 6), round(float(local.y - car.length / 2), 6)])
    out["iccv_2_agent_scenario"] = {"ahead_offsets": offsets}
    print("iccv_2_agent_scenario", offsets)
    (HERE / "reference.json").write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
