"""The history from Python answers as C++ does: every sample verb of the live service and of a
finished recording, asked from Python and with `cpm history [--file] … --json` (the C++ client),
gives the same samples with the same times; a recording's samples iterate and read as columns."""
import json
import os
import signal
import subprocess

import pytest

import cpm
from conftest import wait_until
from cpm.types import Log, VehicleState

BIN = os.environ["CPM_BUILD_BIN"]
N = 30  # samples per car


def cpp(*args):
    """`cpm history …` (the C++ HistoryClient) as JSON lines; its exit code."""
    p = subprocess.run([f"{BIN}/cpm", "history", *args, "--json"], capture_output=True, text=True, timeout=30)
    return [json.loads(line) for line in p.stdout.splitlines() if line.startswith("{")], p.returncode


def same(py_result, cpp_line):
    assert py_result.ok, py_result
    assert (py_result.commit_ns, py_result.data_ns) == (cpp_line["commit_ns"], cpp_line["data_ns"])
    assert py_result.sample.to_dict() == _sorted_like(cpp_line["data"], py_result.sample.to_dict())


def _sorted_like(d, like):
    """The C++ JSON's object in the IDL's field order (json sorts the keys)."""
    if isinstance(like, dict):
        return {k: _sorted_like(d[k], like[k]) for k in like}
    return d


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    db = tmp_path_factory.mktemp("history") / "rec.db"
    svc = subprocess.Popen([f"{BIN}/cpm_history", "--window", "60s", "--record", str(db)], stdout=open(db.with_suffix(".log"), "w"),
                           stderr=subprocess.STDOUT)
    try:
        w = cpm.Writer(VehicleState, "vehicleState", reliable=True, keep_all=True)
        logs = cpm.Writer(Log, "log", reliable=True, transient_local=True, history_depth=100)  # as the topic table says
        assert w.wait_for_matched(1, 15.0), "cpm_history reads vehicleState"
        assert logs.wait_for_matched(1, 15.0)
        t0 = cpm.get_time_ns()
        for i in range(N):
            for car in (1, 2):
                s = VehicleState(vehicle_id=car, speed=car + i / 100)
                cpm.stamp_message(s, t0 + i * 10_000_000, 1_000_000)
                assert w.write(s)
        assert logs.write(Log(id="test", content="a line", log_level=3))
        h = cpm.HistoryClient()
        assert wait_until(lambda: h.latest(VehicleState, "vehicleState", 2).ok and h.latest(VehicleState, "vehicleState", 2).sample.speed == 2 + (N - 1) / 100, 15)
        yield svc, db, h
    finally:  # also when the setup failed
        if svc.poll() is None:
            svc.send_signal(signal.SIGINT)
            svc.wait(30)



def compare_every_verb(h, where):
    """where: [] for the live service, ["--file", db] for a recording."""
    every = h.range(VehicleState, "vehicleState", 2, 0, 2**64 - 1)
    assert every.ok and len(every.samples) == N
    lines, rc = cpp(*where, "range", "--topic", "vehicleState", "--key", "2", "--from", "0", "--to", str(2**64 - 1))
    assert rc == 0 and len(lines) == N
    for r, line in zip(every.samples, lines):
        same(r, line)
    mid = every.samples[N // 2]
    for verb in ("at", "older", "younger"):
        for by, t in (("commit", mid.commit_ns), ("data", mid.data_ns)):
            r = getattr(h, verb)(VehicleState, "vehicleState", 2, t, by=by)
            lines, rc = cpp(*where, verb, "--topic", "vehicleState", "--key", "2", "--time", str(t), "--by", by)
            assert rc == 0, (verb, by)
            same(r, lines[0])
    lines, _ = cpp(*where, "latest", "--topic", "vehicleState", "--key", "1")
    same(h.latest(VehicleState, "vehicleState", 1), lines[0])
    log = h.latest(Log, "log")
    lines, _ = cpp(*where, "latest", "--topic", "log")
    same(log, lines[0])
    # Nothing before the first sample: the same status from both.
    before = h.older(VehicleState, "vehicleState", 2, every.samples[0].commit_ns)
    _, rc = cpp(*where, "older", "--topic", "vehicleState", "--key", "2", "--time", str(every.samples[0].commit_ns))
    assert before.status == "not_found" and before.sample is None and rc == 1
    # The cars' objects (the history's own status grows by one a second while it runs).
    listed = {(o["topic"], o["key"]): o["samples_held"] for o in cpp(*where, "list")[0] if o["topic"] == "vehicleState"}
    ours = {(o.topic, o.key): o.samples_held for o in h.list().objects if o.topic == "vehicleState"}
    assert len(ours) == 2
    assert ours == listed
    return every


def test_every_query_of_the_live_service_from_python_equals_the_cpp_answer(service):
    _, _, h = service
    compare_every_verb(h, [])
    assert h.latest(VehicleState, "vehicleState", 9).status in ("not_found", "unknown_object")


def test_a_recording_read_from_python_equals_cpm_history_file(service):
    svc, db, _ = service
    svc.send_signal(signal.SIGINT)
    assert svc.wait(30) == 0
    run = cpm.open_recording(db)
    every = compare_every_verb(run, ["--file", str(db)])
    iterated = list(run.samples(VehicleState, "vehicleState", 2))
    assert [(r.commit_ns, r.sample) for r in iterated] == [(r.commit_ns, r.sample) for r in every.samples]
    columns = run.table(VehicleState, "vehicleState", 2)
    assert list(columns["speed"]) == [2 + i / 100 for i in range(N)]
    assert list(columns["data_ns"]) == [r.data_ns for r in every.samples]
    assert "pose.x" in columns and "header.create_stamp.nanoseconds" in columns


def test_the_plot_example_draws_a_cars_speed_from_the_recording(service, tmp_path):
    _, db, _ = service  # closed by the test before
    png = tmp_path / "speed.png"
    p = subprocess.run(["/usr/bin/python3", os.path.join(os.environ["CPM_SOURCE_DIR"], "examples/python/plot_speed.py"), str(db), "--vehicle", "2",
                        "--out", str(png)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert f"car 2, {N} states, top speed {2 + (N - 1) / 100:.2f} m/s" in p.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_file_that_is_no_recording_is_named(tmp_path):
    bad = tmp_path / "notes.txt"
    bad.write_text("hello")
    with pytest.raises(cpm.Error, match="notes.txt: not a cpm recording"):
        cpm.open_recording(bad)
