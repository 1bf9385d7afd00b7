"""The ``triton`` engine against real Triton Inference Servers (``tritonserver`` of the nvidia-pytriton wheel).

The servers host the tiny SAD network (:mod:`helpers.tiny_networks`) or PSMNet in a
Python-backend model that runs the ``.onnx`` with ONNX Runtime
(:mod:`helpers.triton_server`): the same KServe v2 protocol and tensors as Triton's
ONNX Runtime backend. The server venv is built once and cached (~/.cache).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from helpers.frames import shifted_pair
from helpers.shared_data import need_shared
from helpers.sinks import CollectSink
from helpers.tiny_networks import sad_stereo
from helpers.triton_server import TritonServer, server_venv, write_model
from helpers.zenoh_loopback import free_port
from vpp_service.cli import EXIT_STARTUP, main
from vpp_service.fusion import Fusion
from vpp_service.matchers import build_matcher
from vpp_service.matchers.model_card import shipped_card
from vpp_service.matchers.triton import ServerUnavailable
from vpp_service.service.pipeline import Pipeline
from vpp_service.sources.base import SourceContext, build_source

D = 16
CARD = {"name": "sad16", "max_disparity": D}
IO = {"left": (1, 3, None, None), "right": (1, 3, None, None)}
OUT = {"disparity": (1, None, None)}


@pytest.fixture(scope="module")
def sad16(tmp_path_factory) -> Path:
    return sad_stereo(tmp_path_factory.mktemp("net") / "sad16.onnx", D)


@pytest.fixture(scope="module")
def repo(tmp_path_factory, sad16) -> Path:
    """A model repository: the SAD network, a slow and a slower copy, a broken one and one the card contradicts."""
    r = tmp_path_factory.mktemp("repo")
    write_model(r, "sad16", sad16, IO, OUT)
    write_model(r, "sad16_slow", sad16, IO, OUT, delay_ms=150)
    write_model(r, "sad16_stuck", sad16, IO, OUT, delay_ms=1000)  # answers after a stop gave up on them
    write_model(r, "sad16_wrong_shape", sad16, IO, OUT, mode="wrong_shape")
    write_model(r, "sad16_other", sad16, {"L": (1, 1, None, None), "right": (1, 3, 64, 64)}, {"disparity": (1, 1, -1)})
    write_model(r, "sad16_fp16", sad16, IO, OUT, dtype="TYPE_FP16")
    return r


@pytest.fixture(scope="module")
def servers(tmp_path_factory, repo):
    """Two servers on the repository (started once for the module, stopped at its end)."""
    venv = server_venv()
    started: list[TritonServer] = []
    try:
        started.extend(TritonServer(venv, repo, tmp_path_factory.mktemp(f"server{i}")).start() for i in range(2))
        yield started
    finally:
        for s in started:
            s.stop()


def remote(url: str | list[str], model: str = "sad16", **opts):
    return build_matcher("onnx", {"engine": "triton", "url": url, "model": model, "card": CARD, **opts})


# ---- the engine on one server ----


def test_remote_disparity_equals_the_local_engines(servers, sad16):
    left, right = shifted_pair(40, 100, 5)
    local = build_matcher("onnx", {"model": str(sad16), "engine": "onnxruntime", "card": CARD})
    m = remote(servers[0].url)
    assert m.check().startswith(f"sad16 card (sad16): triton sad16 on 1 server ({servers[0].url})")
    before = m.network_status()
    assert before is not None
    want, got = local.compute(left, right), m.compute(left, right)
    assert np.array_equal(np.isnan(want), np.isnan(got))
    ok = np.isfinite(want)
    assert ok.mean() > 0.8 and np.max(np.abs(got[ok] - want[ok])) <= 1e-4
    assert np.all(got[:, D:][np.isfinite(got[:, D:])] == 5)  # the known answer, through padding and the wire
    st = m.network_status()
    assert st is not None and st["answered"] == before["answered"] + 1 and st["bad_replies"] == 0
    # the frame crossed once: a pair of float32 tensors out (pad multiple 1: 40 x 100), one disparity back
    assert st["bytes_out"] - before["bytes_out"] == 2 * 3 * 40 * 100 * 4
    assert st["bytes_in"] - before["bytes_in"] == 40 * 100 * 4


def test_metadata_that_disagrees_with_the_card_is_one_line_per_mismatch(servers):
    with pytest.raises(ValueError, match="the served model and the card disagree") as info:
        remote(servers[0].url, "sad16_other").check()
    lines = str(info.value).splitlines()
    assert lines[0] == "matcher.onnx: the served model and the card disagree:"
    body = [ln.strip() for ln in lines[1:]]
    assert "card left_input 'left': triton model 'sad16_other' has no such input (its inputs: ['L', 'right'])" in body
    assert "card input_size [] (dynamic): triton model 'sad16_other' input 'right' is fixed at 64 x 64" in body
    assert "card feeds ['left', 'right']: triton model 'sad16_other' also takes ['L']" in body
    assert len(body) == 3, body
    with pytest.raises(ValueError, match="the served model and the card disagree") as info:
        remote(servers[0].url, "sad16_fp16").check()
    body = [ln.strip() for ln in str(info.value).splitlines()[1:]]
    assert body == [
        "card left_input 'left' is float32 (FP32): triton model 'sad16_fp16' takes FP16",
        "card right_input 'right' is float32 (FP32): triton model 'sad16_fp16' takes FP16",
        "card output 'disparity' is float32 (FP32): triton model 'sad16_fp16' gives FP16",
    ]


def test_a_model_the_server_lacks_names_what_it_has(servers):
    with pytest.raises(RuntimeError, match=r"model 'nope' is not ready \(the server has: sad16/1 \(ready\), "):
        remote(servers[0].url, "nope").check()


def test_a_reply_of_the_wrong_shape_is_counted_and_rejected(servers):
    m = remote(servers[0].url, "sad16_wrong_shape")
    left, right = shifted_pair(32, 64, 3)
    with pytest.raises(ValueError, match=r"output shape \(1, 32, 63\), expected \(1, 32, 64\)"):
        m.compute(left, right)
    st = m.network_status()
    assert st is not None and st["bad_replies"] == 1 and st["answered"] == 1


def test_server_down_at_start(tmp_path, capsys):
    url = f"127.0.0.1:{free_port()}"
    with pytest.raises(ServerUnavailable, match=f"triton server {url}: unreachable"):
        remote(url).check()
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        f'[matcher]\nname = "onnx"\nengine = "triton"\nurl = "{url}"\nmodel = "sad16"\n'
        f"card = {{ name = 'sad16', max_disparity = {D} }}\n"
    )
    rc = main(["run", "--config", str(cfg), "--out", str(tmp_path / "o"), "--check"])
    err = capsys.readouterr().err.strip()
    assert rc == EXIT_STARTUP and len(err.splitlines()) == 1
    assert f"triton server {url}: unreachable" in err


def test_a_server_that_comes_up_late_is_waited_for(tmp_path, repo):
    """At run time a request waits for a server (retry_s) instead of failing the service."""
    server = TritonServer(server_venv(), repo, tmp_path / "late")
    m = remote(server.url, retry_s=90.0)
    left, right = shifted_pair(32, 64, 4)
    out: dict[str, object] = {}

    def match() -> None:
        try:
            out["d"] = m.compute(left, right)
        except Exception as exc:  # noqa: BLE001 - reported by the assert below
            out["error"] = exc

    t = threading.Thread(target=match)
    t.start()
    time.sleep(1.0)
    assert t.is_alive()  # waiting: no server yet
    try:
        server.start()
        t.join(60)
    finally:
        server.stop()
    assert "error" not in out, out.get("error")
    d = out["d"]
    assert isinstance(d, np.ndarray) and np.all(d[:, D:] == 4)


# ---- frames in flight: order, exactly once, a server killed mid-stream ----


def stream(n: int):
    return build_source(
        "sim",
        {"scene": "synthetic", "scene_options": {"height": 48, "width": 96, "max_disparity": 12}, "count": n},
        SourceContext(rig="rig0"),
    )


def run_stream(matcher, n: int, in_flight: int, during=None) -> tuple[Pipeline, list[int]]:
    sink = CollectSink()
    pipe = Pipeline(
        stream(n),
        Fusion(matcher, None, depth=False),
        [sink],
        input_policy="block",
        output_policy="block",
        in_flight=in_flight,
    )
    pipe.start()
    if during is not None:
        during(pipe)
    assert pipe.wait(120), "pipeline did not finish"
    pipe.stop(5.0)
    return pipe, [r.frame.seq for r in sink.results]


def test_two_servers_answer_every_frame_once_in_order(servers, sad16):
    m = remote([s.url for s in servers], "sad16_slow", in_flight=4, max_disparity=D)
    pipe, seqs = run_stream(m, 16, 4)
    assert seqs == list(range(16))
    st = pipe.status()
    assert st["counters"]["published"] == 16 and st["counters"]["dropped"] == 0 and st["counters"]["errors"] == 0
    assert 2 <= st["queues"]["in_flight"]["high_water"] <= 4  # frames were on the servers at once, never more
    net = st["network"]
    per_server = [net["servers"][s.url]["answered"] for s in servers]
    assert min(per_server) >= 4, per_server  # fewest-outstanding dispatch used both
    assert net["retried"] == 0
    local = build_matcher("onnx", {"model": str(sad16), "engine": "onnxruntime", "card": CARD, "max_disparity": D})
    _, local_seqs = run_stream(local, 4, 1)
    assert local_seqs == [0, 1, 2, 3]


def test_a_stop_that_times_out_counts_the_frames_left_on_the_server(servers):
    """Frames on the server when a stop gives up waiting: lost under ``shutdown``, once; late answers ignored."""
    m = remote(servers[0].url, "sad16_stuck", in_flight=4, max_disparity=D, timeout_ms=20_000)
    sink = CollectSink()
    pipe = Pipeline(stream(12), Fusion(m, None, depth=False), [sink], input_size=2, in_flight=4)
    pipe.start()
    assert pipe.source.finished.wait(30)
    deadline = time.monotonic() + 30
    while pipe.status()["queues"]["in_flight"]["len"] < 4 and time.monotonic() < deadline:
        time.sleep(0.01)
    pipe.stop(0.5)  # the server holds each answer 1 s: the stop cannot wait for them
    st = pipe.status()
    c, d = st["counters"], st["dropped"]
    assert c["received"] == 12 and c["errors"] == 0 and d["sink.CollectSink"] == 0
    assert d["shutdown"] >= 4  # the frames on the server
    assert c["published"] + d["shutdown"] + d["input_queue"] == c["received"]  # every frame once
    assert [r.frame.seq for r in sink.results] == list(range(c["published"]))
    while (net := pipe.status()["network"])["answered"] < net["requests"] and time.monotonic() < deadline:
        time.sleep(0.05)  # the server answers late
    assert net["answered"] == net["requests"]
    st = pipe.status()
    assert st["counters"] == c and st["dropped"] == d and len(sink.results) == c["published"]


def test_a_server_killed_mid_stream_loses_no_frame(tmp_path, repo):
    venv = server_venv()
    pair = [TritonServer(venv, repo, tmp_path / f"s{i}").start() for i in range(2)]
    try:
        m = remote([s.url for s in pair], "sad16_slow", in_flight=4, max_disparity=D, timeout_ms=20_000)
        n = 12

        def kill_after_three(pipe: Pipeline) -> None:
            deadline = time.monotonic() + 60
            while pipe.status()["counters"]["published"] < 3 and time.monotonic() < deadline:
                time.sleep(0.01)
            pair[1].kill()

        pipe, seqs = run_stream(m, n, 4, kill_after_three)
        assert seqs == list(range(n))  # every frame, once, in order
        st = pipe.status()
        assert st["counters"]["published"] == n and st["counters"]["dropped"] == 0 and st["counters"]["errors"] == 0
        net = st["network"]
        assert net["retried"] >= 1  # the killed server's frames in flight went to the other one
        assert net["servers"][pair[1].url]["down"] or net["servers"][pair[1].url]["error"]
        assert net["answered"] == n
    finally:
        for s in pair:
            s.stop()


# ---- PSMNet served: the same disparity as the local engine ----


@pytest.mark.slow
def test_psmnet_served_equals_the_local_engine(tmp_path):
    model = need_shared("psmnet_kitti2015.onnx", under="models")
    kitti = need_shared("kitti2012_training")
    from vpp_service.datasets import open_dataset

    frame = open_dataset("auto", kitti, color=True)[0]
    left = np.ascontiguousarray(frame.left[-256:, :352])
    right = np.ascontiguousarray(frame.right[-256:, :352])
    shape = (1, 3, None, None)
    io = {"left": shape, "right": shape}
    write_model(tmp_path / "repo", "psmnet_kitti2015", model, io, {"disparity": (1, None, None)})
    server = TritonServer(server_venv(), tmp_path / "repo", tmp_path / "server").start()
    try:
        m = build_matcher("psmnet", {"engine": "triton", "url": server.url})
        assert m.card == shipped_card("psmnet") and m.triton_settings().model == "psmnet_kitti2015"
        got = m.compute(left, right)
    finally:
        server.stop()
    want = build_matcher("psmnet", {"model": str(model), "engine": "onnxruntime", "threads": 1}).compute(left, right)
    assert np.array_equal(np.isnan(want), np.isnan(got)) and np.isfinite(want).mean() > 0.9
    ok = np.isfinite(want)
    assert np.max(np.abs(got[ok] - want[ok])) <= 1e-3
