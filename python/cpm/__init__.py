"""cpm for Python: the lab's message types, readers and writers, time, the Timer and the
high-level-controller contract (cpm.hlc), over the same C++ library as cpm's programs.

    import sys, cpm
    from cpm.types import VehicleState
    cpm.init(sys.argv)                                   # --dds_domain, --simulated_time, ...
    w = cpm.Writer(VehicleState, "vehicleState", reliable=True)
    s = VehicleState(vehicle_id=3)
    cpm.stamp_message(s, cpm.get_time_ns(), 60_000_000)
    w.write(s)
    r = cpm.Reader(VehicleState, "vehicleState", vehicle_id=3)
    result = r.get_sample(cpm.get_time_ns())             # .sample, .valid, .age_ns

Parameters of the lab (cpm param serve): cpm.parameter_double("max_speed"), parameter_int, …
(they wait up to timeout_s, 5 s, then raise cpm.Error naming the parameter).

Options are keyword arguments named as the C++ options' members (cpm::WriterOptions,
cpm::ReaderOptions). Wrong types or values raise TypeError/ValueError naming the field.
"""
from . import _cpm
from . import types
from . import hlc
from .history import HistoryClient, open_recording
from ._cpm import (Error, Participant, domain_id, get_time_ns, parameter_bool, parameter_double, parameter_doubles, parameter_int,
                   parameter_ints, parameter_string, parameter_uint64_t, simulated_time)

__all__ = ["Error", "Participant", "Writer", "Reader", "ReaderAbstract", "AsyncReader", "MultiVehicleReader", "Timer", "init",
           "get_time_ns", "stamp_message", "log", "simulated_time", "domain_id", "types", "hlc", "HistoryClient", "open_recording",
           "parameter_bool", "parameter_int", "parameter_uint64_t", "parameter_double", "parameter_string", "parameter_ints", "parameter_doubles"]


def init(argv):
    """Reads cpm's flags (--dds_domain, --node_id, --simulated_time, ...) from argv (sys.argv);
    the others are left to the program."""
    _cpm.init([str(a) for a in argv])


def _options(kind, kwargs, where):
    o = getattr(_cpm, kind)()
    for name, value in kwargs.items():
        if not hasattr(o, name):
            known = ", ".join(n for n in dir(o) if not n.startswith("_"))
            raise TypeError(f"{where}: no option {name!r} (options: {known})")
        setattr(o, name, value)
    return o


def _typed(prefix, msg_type, where):
    name = getattr(msg_type, "__name__", None)
    cls = getattr(_cpm, f"{prefix}_{name}", None) if name else None
    if cls is None:
        kind = "keyed topic type (with a vehicle_id key)" if prefix == "MultiVehicleReader" else "topic type"
        raise TypeError(f"{where}: {msg_type!r} is not a lab {kind} (one of cpm.types: {', '.join(types.TOPIC_TYPES)})")
    return cls


def Writer(msg_type, topic, participant=None, **options):
    """A writer of msg_type on topic; write(sample) returns False when DDS refused it."""
    return _typed("Writer", msg_type, "cpm.Writer")(topic, _options("WriterOptions", options, "cpm.Writer"), participant)


def Reader(msg_type, topic, participant=None, **options):
    """The newest sample valid at t: get_sample(t_now) -> result with .sample, .valid, .age_ns."""
    return _typed("Reader", msg_type, "cpm.Reader")(topic, _options("ReaderOptions", options, "cpm.Reader"), participant)


ReaderAbstract = Reader  # cpm_lab's name for the same reader


def AsyncReader(msg_type, topic, callback, participant=None, **options):
    """Calls callback(samples) on cpm's thread for every batch of arriving samples (the GIL taken
    for the call); an exception in it is logged with its traceback and the reader goes on.
    close() ends it."""
    return _typed("AsyncReader", msg_type, "cpm.AsyncReader")(callback, topic, _options("ReaderOptions", options, "cpm.AsyncReader"), participant)


def MultiVehicleReader(msg_type, topic, vehicle_ids, participant=None, **options):
    """One reader for many cars: get_samples(t_now) -> {id: result with .sample, .valid, .age_ns}."""
    ids = list(vehicle_ids)
    for i in ids:
        if not isinstance(i, int) or isinstance(i, bool) or not 1 <= i <= 255:
            raise ValueError(f"cpm.MultiVehicleReader: vehicle id {i!r} is not 1..255")
    return _typed("MultiVehicleReader", msg_type, "cpm.MultiVehicleReader")(topic, ids, _options("ReaderOptions", options, "cpm.MultiVehicleReader"), participant)


def Timer(node_id, period_ns, offset_ns=0, wait_for_start=True, simulated_time_allowed=True, realtime=None):
    """cpm_lab's Timer: start(callback) calls callback(t_nominal_ns) every period on the lab's
    clock (real, or simulated with --simulated_time) until stop(), the lab's stop or Ctrl-C.
    realtime: the callbacks' thread SCHED_FIFO (True, "on", "required"; None: cpm.init's
    --realtime)."""
    return _cpm.Timer(node_id, period_ns, offset_ns, wait_for_start, simulated_time_allowed, realtime)


def stamp_message(message, t_now_ns, expected_delay_ns):
    """create_stamp = t_now_ns, valid_after_stamp = t_now_ns + expected_delay_ns."""
    message.header.create_stamp.nanoseconds = t_now_ns
    message.header.valid_after_stamp.nanoseconds = t_now_ns + expected_delay_ns


class _Log:
    """cpm.log.info(text), .warn, .error, .debug: the lab's log (the log topic and stdout)."""

    def error(self, text):
        _cpm.log(1, str(text))

    def warn(self, text):
        _cpm.log(2, str(text))

    def info(self, text):
        _cpm.log(3, str(text))

    def debug(self, text):
        _cpm.log(4, str(text))

    def __call__(self, text):
        self.info(text)


log = _Log()
