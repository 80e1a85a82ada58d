"""cpm from Python over DDS: every lab type through a Python writer, a typed C++ reader and
writer (py_echo) and back; the newest valid sample; many cars; callbacks on cpm's thread; the
HLC Communicator with this test as its middleware; Ctrl-C."""
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

import cpm
from cpm import types as T
from conftest import wait_until
from test_types import filled

BIN = os.environ["CPM_BUILD_BIN"]


@pytest.fixture(scope="module")
def echo():
    p = subprocess.Popen([f"{BIN}/py_echo"], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().startswith("echoing")
    yield p
    p.send_signal(signal.SIGINT)
    assert p.wait(10) == 0


@pytest.mark.parametrize("name", T.TOPIC_TYPES)
def test_every_topic_type_goes_through_a_cpp_reader_and_writer_and_back_unchanged(echo, name):
    cls = getattr(T, name)
    got = []
    back = cpm.AsyncReader(cls, f"py_out_{name}", lambda samples: got.extend(samples), reliable=True, keep_all=True)
    out = cpm.Writer(cls, f"py_in_{name}", reliable=True, keep_all=True)
    assert out.wait_for_matched(1, 10.0), "py_echo's reader"
    assert wait_until(lambda: back.matched_publications() == 1, 10.0), "py_echo's writer"
    sent = [filled(name, 1), filled(name, 2)]
    for s in sent:
        assert out.write(s)
    assert wait_until(lambda: len(got) == 2, 10.0), f"{len(got)} of 2 came back"
    assert sorted(got, key=repr) == sorted(sent, key=repr)  # two instances: DDS keeps no order between them
    back.close()


def test_a_reader_gives_the_newest_sample_valid_at_t_and_many_cars_at_once():
    w = cpm.Writer(T.VehicleState, "py_state", reliable=True, history_depth=10)
    one = cpm.Reader(T.VehicleState, "py_state", reliable=True, history_depth=10, vehicle_id=2)
    many = cpm.MultiVehicleReader(T.VehicleState, "py_state", [1, 2, 3], reliable=True, history_depth=10)
    assert w.wait_for_matched(2, 5.0)
    t = cpm.get_time_ns()
    # car 2: a newer sample (created at t + 1) that is valid only a second later
    for vid, speed, created, valid_after in ((1, 0.1, t, t), (2, 0.2, t, t), (2, 0.3, t + 1, t + 10**9)):
        s = T.VehicleState(vehicle_id=vid, speed=speed)
        s.header.create_stamp.nanoseconds = created
        s.header.valid_after_stamp.nanoseconds = valid_after
        assert w.write(s)
    assert wait_until(lambda: one.get_sample(t + 1000).valid)
    now = one.get_sample(t + 1000)
    assert now.sample.speed == 0.2 and now.age_ns == 1000, "the newer one is not valid yet"
    assert wait_until(lambda: one.get_sample(t + 2 * 10**9).sample.speed == 0.3), "and is, a second later"
    results = many.get_samples(t + 1000)
    assert sorted(results) == [1, 2, 3]
    assert results[1].valid and results[1].sample.speed == 0.1
    assert not results[3].valid


def test_an_exception_in_a_callback_is_logged_and_the_reader_goes_on(capfd):
    calls = []

    def callback(samples):
        calls.append(len(samples))
        if len(calls) == 1:
            raise ZeroDivisionError("the first batch")

    r = cpm.AsyncReader(T.StopRequest, "py_stop", callback, reliable=True, keep_all=True)
    w = cpm.Writer(T.StopRequest, "py_stop", reliable=True, keep_all=True)
    assert w.wait_for_matched(1, 5.0)
    assert w.write(T.StopRequest(vehicle_id=1))
    assert wait_until(lambda: len(calls) == 1)
    assert w.write(T.StopRequest(vehicle_id=2))
    assert wait_until(lambda: len(calls) == 2), "the reader went on"
    r.close()
    err = capfd.readouterr()
    assert "ZeroDivisionError: the first batch" in err.out + err.err


class Middleware:
    """The middleware's side of the HLC contract, played by the test."""

    def __init__(self, participant):
        self.answers = []
        self.lists = cpm.Writer(T.VehicleStateList, "vehicleStateList", participant, reliable=True)
        self.triggers = cpm.Writer(T.SystemTrigger, "systemTrigger", participant, reliable=True, transient_local=True)
        self.ready = cpm.AsyncReader(T.ReadyStatus, "readyStatus", self.on_ready, participant, reliable=True, transient_local=True,
                                     history_depth=64)

    def on_ready(self, samples):
        self.answers.extend(s.next_start_stamp.nanoseconds for s in samples if s.source_id == "hlc")

    def send(self, t_now):
        assert self.lists.write(T.VehicleStateList(t_now=t_now, period_ms=100, active_vehicle_ids=[1, 2]))

    def stop(self):
        s = T.SystemTrigger()
        s.next_start.nanoseconds = 2**64 - 1
        assert self.triggers.write(s)


def test_a_python_controller_answers_each_list_and_a_step_that_raises_is_counted_and_the_controller_goes_on(capfd, extra_domain):
    # A domain of its own, as a controller has: the lab's stop it is sent would stop this
    # process's other timers too.
    own = cpm.Participant(domain_id=extra_domain)
    lab = Middleware(own)
    hlc = cpm.hlc.Communicator([1, 2], own)
    seen, stopped = [], []

    def step(state_list):
        seen.append(state_list.t_now)
        if state_list.t_now == 200:
            raise KeyError("no such car")

    hlc.on_each_timestep(step)
    hlc.on_stop(lambda: stopped.append(True))
    runner = threading.Thread(target=hlc.start)
    runner.start()
    assert wait_until(lambda: 2**64 - 1 in lab.answers), "the controller announces itself"
    assert lab.lists.wait_for_matched(1, 5.0)
    for t in (100, 200, 300):
        lab.send(t)
        assert wait_until(lambda: len(seen) == t // 100)
        if t != 200:
            assert wait_until(lambda: t in lab.answers)
        else:
            assert wait_until(lambda: hlc.failed_steps == 1)
    lab.stop()
    runner.join(5)
    assert not runner.is_alive(), "the lab's stop ends start()"
    assert stopped == [True]
    assert seen == [100, 200, 300] and 200 not in lab.answers
    assert (hlc.steps, hlc.failed_steps) == (2, 1)
    out = capfd.readouterr()
    assert "KeyError: 'no such car'" in out.out + out.err, "the traceback is logged"


def test_ctrl_c_stops_a_python_controller_that_waits_in_cpm(extra_domain):
    script = "import sys, cpm\ncpm.init(sys.argv)\nh = cpm.hlc.Communicator([1])\nh.on_each_timestep(lambda l: None)\nprint('waiting', flush=True)\nh.start()\n"
    p = subprocess.Popen([sys.executable, "-c", script, "--dds_domain", str(extra_domain)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ))
    assert p.stdout.readline().strip() == "waiting"
    time.sleep(0.3)
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=10)
    assert time.monotonic() - t0 < 3
    assert p.returncode != 0 and "KeyboardInterrupt" in err


def test_a_timer_calls_back_on_its_period_and_stop_ends_it():
    timer = cpm.Timer("py_timer", 10_000_000, 0, wait_for_start=False)
    ticks = []

    def tick(t):
        ticks.append(t)
        if len(ticks) == 5:
            timer.stop()

    timer.start(tick)  # returns once stopped
    assert len(ticks) == 5
    # On the period's grid, in order; a tick the machine was too busy for is skipped, not
    # called late, and counted (a busy CI machine skips one now and then).
    assert all(b > a and (b - a) % 10_000_000 == 0 for a, b in zip(ticks, ticks[1:])), ticks
    assert all(t % 10_000_000 == 0 for t in ticks)
    skipped = sum((b - a) // 10_000_000 - 1 for a, b in zip(ticks, ticks[1:]))
    assert skipped <= timer.missed_deadlines, (ticks, timer.missed_deadlines)


def test_a_timer_runs_its_callbacks_in_real_time_when_asked_and_a_wrong_mode_is_named():
    with pytest.raises(cpm.Error, match="Timer realtime: 'sometimes' is not one of on, off, required"):
        cpm.Timer("py_rt_bad", 10_000_000, 0, wait_for_start=False, realtime="sometimes")
    timer = cpm.Timer("py_rt", 10_000_000, 0, wait_for_start=False, realtime=True)
    policies = []

    def tick(t):
        policies.append(os.sched_getscheduler(0))  # this thread's
        if len(policies) == 3:
            timer.stop()

    timer.start(tick)
    # root (as here and in CI) may; a user without the privilege runs as before
    expected = os.SCHED_FIFO if os.geteuid() == 0 else os.SCHED_OTHER
    assert policies == [expected] * 3
    assert os.sched_getscheduler(0) == os.SCHED_OTHER, "the thread's own policy came back"


def test_an_exception_in_a_timer_callback_ends_start_with_it():
    timer = cpm.Timer("py_timer_raises", 10_000_000, 0, wait_for_start=False)

    def tick(t):
        raise ValueError("bad tick")

    with pytest.raises(cpm.Error, match="ValueError: bad tick"):
        timer.start(tick)


def test_the_labs_parameters_are_read_from_python(tmp_path):
    params = tmp_path / "params.json"
    params.write_text('{"max_speed": 1.5, "lanes": 3, "name": "ring", "gains": [0.5, 2.0], "on": true}')
    server = subprocess.Popen([f"{BIN}/cpm", "param", "serve", str(params)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        assert cpm.parameter_double("max_speed", 10.0) == 1.5
        assert cpm.parameter_int("lanes") == 3
        assert cpm.parameter_string("name") == "ring"
        assert cpm.parameter_doubles("gains") == [0.5, 2.0]
        assert cpm.parameter_bool("on") is True
        with pytest.raises(cpm.Error, match="max_speed"):
            cpm.parameter_int("max_speed")  # another type: named
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(10)
