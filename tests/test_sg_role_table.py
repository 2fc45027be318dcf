"""The straight road's roles are Role members chosen from one ordered table, and the pedestrian's abilities come
from the one capability table (CAN_DO)."""

import ast
import typing
from pathlib import Path

from dv2s_gym.pipeline.semantics.text import elements_from_text
from dv2s_gym.pipeline.sg.rules import generate_rules, lane_roles
from dv2s_gym.pipeline.sg.rules.frame import ActorFrame
from dv2s_gym.pipeline.sg.rules.roles import Role
from scenario_bank.elements import CAN_DO

RULES = Path(lane_roles.__file__).parent


def test_actor_role_is_typed_as_the_role_enum():
    assert typing.get_type_hints(ActorFrame)["role"] == typing.Optional[Role]
    assert ActorFrame("car0", "car").role is None


def test_assigned_roles_are_role_members():
    result = generate_rules("On a highway a car ahead of the ego brakes hard while a truck drives in the left lane "
                            "and a pedestrian crosses the road.", seed=0)
    roles = [a.role for a in result.frame.actors]
    assert roles and all(isinstance(r, Role) for r in roles), roles
    assert Role.LEAD in roles and Role.CROSSER in roles


def test_no_role_is_compared_with_a_string():
    found = []
    for path in sorted(RULES.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare) and isinstance(node.left, ast.Attribute) and node.left.attr == "role":
                for right in node.comparators:
                    for leaf in ast.walk(right):
                        if isinstance(leaf, ast.Constant) and isinstance(leaf.value, str):
                            found.append(f"{path.name}:{node.lineno}")
    assert not found, found


def test_first_role_reads_an_ordered_table():
    table = lane_roles._ROLE_RULES
    assert len(table) >= 10
    assert all(callable(cond) and (isinstance(role, Role) or callable(role)) for cond, role in table)


def test_pedestrian_abilities_are_read_from_can_do():
    # a pedestrian sharing a verb with a car takes only the actions a pedestrian can do
    elements = elements_from_text("A car and a pedestrian collide in front of the ego on a town street.")
    assert ("pedestrian", "collide") in elements.actions
    for path in [RULES / "lane_roles.py", RULES / "junctions.py", Path(lane_roles.__file__).parents[2] / "semantics" / "action_rules.py"]:
        text = path.read_text()
        assert '"cross", "stop", "collide"' not in text, path
        assert 'CAN_DO[ActorKind.PEDESTRIAN]' in text, path
    assert {"cross", "stop", "collide"} <= CAN_DO["pedestrian"]
