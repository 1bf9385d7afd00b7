"""``vpp-service view`` between processes on loopback, its Rerun recordings read back."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from rerun.chunk import RrdReader

from helpers.frames import make_frame
from helpers.rerun_rrd import read_rrd
from helpers.zenoh_loopback import zenoh_test_config
from vpp_service.cli.view import decode_part, rig_path
from vpp_service.frame import FusionResult
from vpp_service.sinks.base import SinkContext, build_sink
from vpp_service.transport import wire

ROOT = Path(__file__).resolve().parents[1]


def vpp(*argv: str, **kw) -> subprocess.Popen:
    """``python -m vpp_service ...`` running this checkout's code."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "vpp_service", *argv],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def finish(proc: subprocess.Popen, timeout: float) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"timed out; stderr: {err[-2000:]}")
    return proc.returncode, out, err


def test_view_records_a_running_service(tmp_path, zenoh_endpoint):
    """The service in one process, ``view --save`` in another; the .rrd read back."""
    cfg = tmp_path / "svc.toml"
    cfg.write_text(
        f'[service]\nrig = "rigT"\nsummary = false\nout = "{tmp_path / "out"}"\n'
        f'[zenoh]\nlisten = ["{zenoh_endpoint}"]\n'
        '[source]\ntype = "sim"\nscale = 0.5\nrate_hz = 5.0\n'
        '[matcher]\nname = "sgbm"\nmax_disparity = 64\n'
        '[[sinks]]\ntype = "zenoh"\n'
    )
    service = vpp("run", "--config", str(cfg))
    try:
        time.sleep(1.0)
        rrd = tmp_path / "watch.rrd"
        view = vpp("view", "--rig", "rigT", "--connect", zenoh_endpoint, "--save", str(rrd), "--max-frames", "6")
        rc, out, err = finish(view, 90)
    finally:
        service.send_signal(signal.SIGINT)
        finish(service, 30)
    assert rc == 0, err[-2000:]
    summary = json.loads(out)  # stdout is pure JSON: the banner goes to stderr
    assert "view: watching vpp/rigT/out/*" in err
    got = summary["rigs"]["rigT"]
    assert got["received"]["disparity"] == 6 and got["rerun"]["errors"] == 0 and summary["rejected"] == 0
    assert summary["saved"] == [str(rrd)]

    reader = RrdReader(rrd)
    assert [r.application_id for r in reader.recordings()] == ["vpp-service-rigT"]
    data = read_rrd(rrd)
    assert len(data["/rigT/disparity"]["seq"]) == 6
    disp = data["/rigT/disparity"]
    assert disp["DepthImage:colormap"][0] is not None and disp["DepthImage:depth_range"][0] is not None
    # what the service published on request, each on its own entity (the on-request outputs start once the
    # service sees the subscriber match, so the first frames of a loaded machine may come without them)
    expected = {"/rigT/left", "/rigT/right", "/rigT/left/sparse", "/rigT/camera", "/rigT/camera/depth"}
    assert expected <= set(data), sorted(data)
    assert data["/rigT/left"]["EncodedImage:media_type"][0] == ["image/jpeg"]
    assert any(e.startswith("/rigT/timing/") for e in data)


@pytest.mark.parametrize("rigs", [("rig0", "rig1"), ("rig0",)])
def test_view_wildcard_keeps_one_recording_per_rig(tmp_path, zenoh_endpoint, rigs):
    """A publisher of outputs for each rig (this process), ``view --rig '*'`` in another process.

    Several rigs: one file per rig, ``all-<rig>.rrd``; one rig: the file asked for, ``all.rrd``.
    """
    rrd = tmp_path / "all.rrd"
    with zenoh.open(zenoh_test_config(listen=[zenoh_endpoint])) as session:
        sinks = {
            rig: build_sink(
                "zenoh",
                {
                    "outputs": ["disparity", "depth", "confidence", "left_vpp", "right_vpp", "sparse"],
                    "image_enc": "png",
                },
                SinkContext(rig=rig, session=session),
            )
            for rig in rigs
        }
        for s in sinks.values():
            s.open()
        view = vpp("view", "--rig", "*", "--connect", zenoh_endpoint, "--save", str(rrd), "--max-frames", "8")
        sent: dict[str, dict[int, np.ndarray]] = {rig: {} for rig in rigs}
        seq, deadline = 0, time.monotonic() + 60
        while view.poll() is None and time.monotonic() < deadline:
            for k, (rig, sink) in enumerate(sinks.items()):
                fr = make_frame().with_(rig=rig, seq=seq)
                sparse = np.full(fr.shape, np.nan, np.float32)
                sparse[2, 3] = 4.0
                disp = np.full(fr.shape, 3.0 + k + 0.01 * seq, np.float32)
                sent[rig][seq] = disp
                sink.write(
                    FusionResult(
                        frame=fr.with_(sparse_disparity=sparse),
                        disparity=disp,
                        depth=np.full(fr.shape, 2.0, np.float32),
                        confidence=np.full(fr.shape, 0.75, np.float32),
                        left_vpp=fr.left,
                        right_vpp=fr.right,
                    )
                )
            seq += 1
            time.sleep(0.1)
        rc, out, err = finish(view, 30)
        for s in sinks.values():
            s.close(2.0)
    assert rc == 0, err[-2000:]
    summary = json.loads(out.strip().splitlines()[-1])
    assert sorted(summary["rigs"]) == list(rigs)
    files = {rig: tmp_path / (f"all-{rig}.rrd" if len(rigs) > 1 else "all.rrd") for rig in rigs}
    assert sorted(summary["saved"]) == [str(f) for f in files.values()]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f.name for f in files.values())
    assert f"view: wrote {', '.join(summary['saved'])}" in err
    for rig in rigs:
        path = files[rig]
        assert [r.application_id for r in RrdReader(path).recordings()] == [f"vpp-service-{rig}"]
        data = read_rrd(path)
        assert {e.split("/")[1] for e in data} == {rig}  # only this rig's entities
        assert {
            f"/{rig}/disparity",
            f"/{rig}/confidence",
            f"/{rig}/left",
            f"/{rig}/right",
            f"/{rig}/left/sparse",
        } <= set(data)
        disp = data[f"/{rig}/disparity"]
        for s, buf in zip(disp["seq"], disp["DepthImage:buffer"], strict=True):
            values = np.frombuffer(bytes(np.asarray(buf[0], np.uint8)), np.float32)
            assert np.array_equal(values, sent[rig][s].ravel())
        pts = data[f"/{rig}/left/sparse"]["Points2D:positions"][0]
        assert np.allclose(pts, [[3.5, 2.5]])


def test_decode_part_rejects_a_foreign_rig():
    fr = make_frame().with_(rig="rigA")
    res = FusionResult(frame=fr, disparity=np.ones(fr.shape, np.float32))
    payload = wire.encode_output(res, "disparity")
    assert decode_part("disparity", payload, "rigA").disparity is not None
    res.confidence = np.full(fr.shape, 0.5, np.float32)
    conf = decode_part("confidence", wire.encode_output(res, "confidence"), "rigA").confidence
    assert conf is not None and np.array_equal(conf, res.confidence)
    with pytest.raises(wire.WireError, match="rig"):
        decode_part("disparity", payload, "rigB")


def test_rig_path():
    assert rig_path("x/w.rrd", "r1", wildcard=False) == "x/w.rrd"
    assert rig_path("x/w.rrd", "r1", wildcard=True) == str(Path("x/w-r1.rrd"))


def test_viewer_logs_messages_as_they_come_and_counts_the_gaps(tmp_path):
    """Each output is logged in arrival order; seq values skipped are gaps, per output; a restart is not one."""
    from vpp_service.cli.view import Viewer

    viewer = Viewer({"mode": "save", "path": str(tmp_path / "v.rrd"), "max_hz": 0, "queue_size": 64}, False)
    logged: list[int] = []
    submit = viewer.sink("r1").submit
    viewer.sinks["r1"].submit = lambda parts: (logged.append(parts.seq), submit(parts))  # type: ignore[method-assign]
    seqs = (0, 1, 3, 4, 8, 2, 3)  # 2 and 5-7 never come; then the service restarts at 2
    for seq in seqs:
        fr = make_frame(depth="disparity").with_(rig="r1", seq=seq)
        res = FusionResult(fr, np.full(fr.shape, float(seq), np.float32))
        assert viewer.handle("vpp/r1/out/disparity", wire.encode_output(res, "disparity")) == "disparity"
        if seq in (0, 1, 8):
            assert viewer.handle("vpp/r1/out/sparse", wire.encode_output(res, "sparse")) == "sparse"
    summary = viewer.close()
    assert logged == [0, 0, 1, 1, 3, 4, 8, 8, 2, 3]
    rig = summary["rigs"]["r1"]  # type: ignore[index]
    assert rig["gaps"] == {"disparity": 1 + 3, "sparse": 6} and rig["received"] == {"disparity": 7, "sparse": 3}
    assert read_rrd(tmp_path / "v.rrd")["/r1/disparity"]["seq"] == sorted(seqs)  # the recording, on its seq timeline


def test_view_to_a_closed_port_says_it_could_not_connect(tmp_path, capsys):
    from helpers.zenoh_loopback import free_port
    from vpp_service.cli import EXIT_FAILURE, main

    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    rc = main(["view", "--connect", endpoint, "--save", str(tmp_path / "v.rrd"), "--duration", "5"])
    captured = capsys.readouterr()
    assert rc == EXIT_FAILURE and f"could not connect to {endpoint}" in captured.err
    assert not (tmp_path / "v.rrd").exists()


def test_view_cannot_spawn_a_viewer_without_a_display(monkeypatch, capsys):
    from vpp_service.cli import EXIT_STARTUP, main

    monkeypatch.setattr("sys.platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "--duration", "1"]) == EXIT_STARTUP
    err = capsys.readouterr().err
    assert "cannot spawn a Rerun viewer: no display here" in err and "--save" in err
