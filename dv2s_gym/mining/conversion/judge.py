"""The judge of a converted script: the checks it must pass to be kept, each failing one a rejection with its own
stage (:func:`judge_conversion`): the failure's interaction shown, the failure reproduced, the reference driver
avoiding it, the failure's actors kept, and the failing parameter values inside the new script's ranges (with at
least :data:`COMPARED_SHARE` of them compared).
"""

from __future__ import annotations

from typing import Any, List, Mapping, Optional

from dv2s_gym.mining.conversion.interaction import FailureInteraction
from dv2s_gym.mining.conversion.ranges import exact_number
from dv2s_gym.mining.conversion.rejection import ConversionRejected
from dv2s_gym.mining.report_text import not_compared_names_text
from dv2s_gym.mining.conversion.scenic_values import support_text
from scenario_bank.records import Failure

__all__ = ["judge_conversion", "COMPARED_SHARE"]


COMPARED_SHARE = 0.5
"""The judge rejects a new scenario when it could compare fewer than this share of the failure's parameters with
the new script's ranges: with most of them unchecked, a script could drop or change what made the scene fail and
still pass (docs/mining.md). Whatever the share, a key parameter (one that sets a quantity of the failure's
interaction: the ego's or the key actor's, ``compare_parameters``' ``"key"``) that the new script sets with a
parameter of its own must be compared and contain the failing value: one not comparable is a rejection with its
reason (``"key_not_compared"``, :func:`_key_not_compared`). Within the share may go unchecked: parameters of other
actors (traffic beside the interaction), and key quantities the new script fixes without a parameter of its own or
leaves out (a generated script parameterises a scene its own way: the rule-based generator leaves most behaviour
timings fixed), as long as a fixed key quantity holds the failing value (``"key_fixed_outside"``,
:func:`~dv2s_gym.mining.conversion.keys.key_fixed_outside`); a key actor's placement the new script writes in a form the
judge cannot read is a rejection (``"key_unread"``, :func:`~dv2s_gym.mining.conversion.keys.key_placement_unread`)."""


_KEY_REJECTIONS = (
    ("key_fixed_outside", "that the new script fixes must hold the failing value, and it does not"),
    ("key_overridden", "that the new script passes to a behaviour must be what the behaviour uses, and the behaviour "
                       "assigns it anew"),
    ("key_unread", "is placed by another quantity or form, from which the judge cannot read it, so the failing value "
                   "is not checked"),
)
"""The key-parameter findings of :func:`~dv2s_gym.mining.conversion.parameters.compare_parameters` that reject a
conversion, each with what is wrong, in the order the rejection reasons list them."""


def judge_conversion(out: Mapping[str, Any], interaction: FailureInteraction,
                     source_failure: Failure, threshold: float) -> List[ConversionRejected]:
    """The checks a converted script must pass, each failing one a rejection with its own stage:
    ``interaction`` (its runs show the failure's actor doing its manoeuvre), ``reproduction`` (the policy
    fails the same way with the same kind of actor), ``avoidability`` (the reference driver drives most
    episodes without any collision, off-road or stall), ``actors`` (the script's actors are the failure's, kind
    for kind: none missing, the adversary above all, none added; ``out["actors"]``,
    :func:`~dv2s_gym.mining.conversion.episodes.compare_actors`) and ``parameters`` (the script's ranges of the
    failure's parameters contain the failing values; ``out["parameters"]``,
    :func:`~dv2s_gym.mining.conversion.parameters.compare_parameters`)."""
    found: List[ConversionRejected] = []
    repro = out["reproduction"]
    k = repro["k"]
    what = f"{interaction.kind} ({', '.join(interaction.manoeuvres or ()) or 'no manoeuvre'})"
    if interaction.kind and repro["interaction_shown"] / k < threshold:
        found.append(ConversionRejected("interaction", f"the new scenario's runs show the failure's {what} in "
                                                       f"{repro['interaction_shown']} of {k} episodes (share "
                                                       f"{repro['interaction_shown'] / k:.2f} < threshold "
                                                       f"{threshold:g})"))
    if repro["rate"] < threshold:
        with_kind = f" with a {interaction.kind}" if interaction.kind else ""
        found.append(ConversionRejected("reproduction", f"the new scenario reproduced the {source_failure.type} "
                                                        f"failure{with_kind} in {repro['reproduced']} of {k} episodes "
                                                        f"(rate {repro['rate']:.2f} < threshold {threshold:g})"))
    avoid = out.get("avoidability")
    if avoid and not avoid["avoided_rate"] > 0.5:
        classes = ", ".join(f"{label} {n}" for label, n in (avoid.get("failures") or {}).items())
        found.append(ConversionRejected("avoidability", f"the reference driver {avoid['reference']} failed in "
                                                        f"{avoid['failed']} of {avoid['k']} episodes of the new "
                                                        f"scenario"
                                                        + (f" ({classes})" if classes else "")
                                                        + "; it must drive most of them without any collision, "
                                                          "off-road or stall"))
    actors = out.get("actors")
    if actors and not actors.get("same"):
        adversary = actors.get("adversary")
        problems = []
        if adversary and adversary in actors.get("missing", {}) and not actors["script"].get(adversary):
            problems.append(f"the failure's adversary, a {adversary}, is missing")
        problems += [f"{n} {kind} fewer" for kind, n in actors.get("missing", {}).items()
                     if not (kind == adversary and not actors["script"].get(adversary))]
        problems += [f"{n} {kind} more" for kind, n in actors.get("extra", {}).items()]
        if not problems and actors.get("runs") and 2 * actors.get("runs_matching", 0) <= actors["runs"]:
            problems.append(f"the failure's actors, kind for kind, in only {actors['runs_matching']} of "
                            f"{actors['runs']} runs (a majority needed)")
        found.append(ConversionRejected("actors", f"the failure's scene has {_census_text(actors['failure'])}, the "
                                                  f"new scenario's {_census_text(actors['script'])}: "
                                                  f"{', '.join(problems)}"))
    parameters = out.get("parameters")
    for field, problem in _KEY_REJECTIONS:
        listed = (parameters or {}).get(field) or {}
        if listed:
            reasons = "; ".join(f"{name} ({why})" for name, why in sorted(listed.items()))
            found.append(ConversionRejected("parameters", f"a key quantity (of the failure's interaction) {problem}: "
                                                          f"{reasons}"))
    unchecked_key = _key_not_compared(parameters)
    if unchecked_key:
        found.append(ConversionRejected("parameters", unchecked_key))
    few = _too_few_compared(parameters)
    if few:
        found.append(ConversionRejected("parameters", few))
    if parameters and parameters.get("outside"):
        unchecked = parameters.get("not_comparable") or {}
        found.append(ConversionRejected("parameters", "the new scenario's ranges do not contain the failing values: "
                                        + ", ".join(_outside_text(name, parameters["compared"][name])
                                                    for name in parameters["outside"])
                                        + (f" (not compared: {not_compared_names_text(unchecked)})"
                                           if unchecked else "")))
    return found


def _key_not_compared(parameters: Optional[Mapping[str, Any]]) -> Optional[str]:
    """The rejection for key parameters (``parameters["key"]``) the judge could not compare, each with the quantity
    it sets and why, or ``None``."""
    if not parameters:
        return None
    missing = parameters.get("key_not_compared") or {}
    if not missing:
        return None
    return ("a key parameter (it sets a quantity of the failure's interaction) that the new script sets with a "
            "parameter of its own must be compared, and the judge could not: " + "; ".join(
                f"{name} ({why})" for name, why in sorted(missing.items())))


def _too_few_compared(parameters: Optional[Mapping[str, Any]]) -> Optional[str]:
    """The rejection for a comparison of fewer than :data:`COMPARED_SHARE` of the failing parameters, or ``None``."""
    if not parameters:
        return None
    compared, unchecked = parameters.get("compared") or {}, parameters.get("not_comparable") or {}
    total = len(compared) + len(unchecked)
    if not total or len(compared) >= COMPARED_SHARE * total:
        return None
    return (f"only {len(compared)} of the failure's {total} parameters could be compared with the new script, fewer "
            f"than half: " + "; ".join(f"{name}: {reason}" for name, reason in sorted(unchecked.items())))


def _outside_text(name: str, comparison: Mapping[str, Any]) -> str:
    """``name = value outside low..high``, every number exact (10.00001 against 5..10 is not "10"), so a value
    outside never prints as one inside."""
    low, high = comparison["range"]
    spelled = f" (the script's {comparison['script_name']})" if comparison.get("script_name") else ""
    if comparison.get("by") == "meaning":
        spelled = f" (the script's {comparison['script_name']}: {comparison.get('basis')})"
    where = f" (as the {comparison['where']})" if comparison.get("where") else ""
    if comparison.get("jointly"):
        return (f"{name} = {exact_number(float(comparison['value']))}, which the parent's "
                f"{comparison['parent_expression']} makes {exact_number(float(comparison['quantity']))} as "
                f"{comparison['jointly']}, outside {exact_number(float(comparison['interval'][0]))}.."
                f"{exact_number(float(comparison['interval'][1]))}, the interval the new script's "
                f"{comparison['expression']} takes with its parameters that stand for "
                f"compared ones at their failing values and the others over their ranges")
    if comparison.get("interval"):
        own = comparison.get("script_name", name)
        parent = (f", which the parent's {comparison['parent_expression']} makes "
                  f"{exact_number(float(comparison['quantity']))}," if comparison.get("parent_expression") else "")
        start, end = comparison["interval"]
        if comparison.get("support") and start - 1e-9 <= float(comparison["quantity"]) <= end + 1e-9:
            return (f"{name}{spelled} = {exact_number(float(comparison['value']))}{parent} not among the values "
                    f"the new script's {comparison['expression']} takes with {own} one of "
                    f"{support_text(comparison['support'])}{where}")
        return (f"{name}{spelled} = {exact_number(float(comparison['value']))}{parent} outside "
                f"{exact_number(float(start))}..{exact_number(float(end))}, the interval the new script's "
                f"{comparison['expression']} takes with {own} in {exact_number(float(low))}.."
                f"{exact_number(float(high))}{where}")
    if comparison.get("support") and low - 1e-9 <= float(comparison["value"]) <= high + 1e-9:
        return (f"{name}{spelled} = {exact_number(float(comparison['value']))} not among the values "
                f"{comparison.get('script_name', name)} takes ({support_text(comparison['support'])}){where}")
    return (f"{name}{spelled} = {exact_number(float(comparison['value']))} outside "
            f"{exact_number(float(low))}..{exact_number(float(high))}{where}")


def _census_text(census: Mapping[str, int]) -> str:
    total = sum(census.values())
    return f"{total} actor{'' if total == 1 else 's'}" + (
        f" ({', '.join(f'{kind} {n}' for kind, n in census.items())})" if census else "")
