"""The lab's history from Python: the live service (cpm_history) and finished runs' recordings
answer the same questions, as `cpm history` and `cpm history --file` do.

    h = cpm.HistoryClient()                                  # the live service on the domain
    r = h.at(VehicleState, "vehicleState", 3, cpm.get_time_ns() - 2_000_000_000)
    if r.ok: print(r.sample.pose.x, r.commit_ns, r.data_ns)
    run = cpm.open_recording("runs/…/recording.db")          # the same verbs, from the file
    for r in run.samples(VehicleState, "vehicleState", 3): ...
    columns = run.table(VehicleState, "vehicleState", 3)    # {"data_ns": [...], "speed": [...], "pose.x": [...], ...}

Times are nanoseconds; `by` is "commit" (when the history received it) or "data" (create_stamp).
Statuses are the service's: ok, not_found, evicted, not_yet, timeout, gap, partial,
unknown_object, error.
"""
from . import _cpm
from .types import HistoryRequest

ALL_TIME = (0, 2**64 - 1)


class Result:
    """One sample's answer: status, sample (None unless ok), its times and the error, if any."""

    __slots__ = ("status", "sample", "commit_ns", "data_ns", "valid_after_ns", "source_ns", "error")

    def __init__(self, status, sample=None, commit_ns=0, data_ns=0, valid_after_ns=0, source_ns=0, error=""):
        self.status, self.sample, self.error = status, sample, error
        self.commit_ns, self.data_ns, self.valid_after_ns, self.source_ns = commit_ns, data_ns, valid_after_ns, source_ns

    ok = property(lambda self: self.status == "ok")

    def __repr__(self):
        return f"Result(status={self.status!r}, commit_ns={self.commit_ns}, data_ns={self.data_ns}, sample={self.sample!r})"


class Range:
    """A range's answer: status, samples (Results), truncated (more matched than the limit), lost."""

    def __init__(self, status, samples, truncated, lost, error):
        self.status, self.samples, self.truncated, self.lost, self.error = status, samples, truncated, lost, error

    ok = property(lambda self: self.status == "ok")

    def __repr__(self):
        return f"Range(status={self.status!r}, {len(self.samples)} samples, truncated={self.truncated}, lost={self.lost})"


def _decoder(msg_type):
    name = getattr(msg_type, "__name__", "")
    decode = getattr(_cpm, f"decode_{name}", None)
    if decode is None:
        raise TypeError(f"{msg_type!r} is not a lab topic type")
    return decode


def _result(msg_type, status, s, error=""):
    sample = None
    if s is not None and (s.status or status) in ("ok", "partial"):
        sample = _decoder(msg_type)(s.payload)
        if sample is None:
            return Result("error", None, s.commit_ns, s.data_ns, s.valid_after_ns, s.source_ns, f"the payload is no {msg_type.__name__}")
    if s is None:
        return Result(status, None, error=error)
    return Result(s.status or status, sample, s.commit_ns, s.data_ns, s.valid_after_ns, s.source_ns, error)


class HistoryClient:
    """Asks the lab's history service (the process's participant, or `participant`)."""

    def __init__(self, participant=None, reply_timeout_s=3.0, _client=None):
        self._c = _client if _client is not None else _cpm.HistoryClient(participant, reply_timeout_s)

    def request(self, kind, topic="", key="", **fields):
        """Any request (kind: latest, at, older, younger, range, wait_next, successor, snapshot,
        info, search, list, wait_object, changes; the other HistoryRequest fields as keywords):
        the service's HistoryReply as it is."""
        rq = HistoryRequest(kind=kind, topic=topic, key=str(key), **fields)
        return self._c.request(rq)

    def _one(self, kind, msg_type, topic, key, **fields):
        reply = self.request(kind, topic, key, **fields)
        return _result(msg_type, reply.status, reply.samples[0] if reply.samples else None, reply.error)

    def latest(self, msg_type, topic, key=""):
        return self._one("latest", msg_type, topic, key)

    def at(self, msg_type, topic, key, t, by="commit"):
        return self._one("at", msg_type, topic, key, t0=t, by=by)

    def older(self, msg_type, topic, key, t, by="commit"):
        return self._one("older", msg_type, topic, key, t0=t, by=by)

    def younger(self, msg_type, topic, key, t, by="commit"):
        return self._one("younger", msg_type, topic, key, t0=t, by=by)

    def successor(self, msg_type, topic, key, after, timeout_ns=0):
        return self._one("successor", msg_type, topic, key, t0=after, timeout_ns=timeout_ns)

    def wait_next(self, msg_type, topic, key, after, timeout_ns):
        return self._one("wait_next", msg_type, topic, key, t0=after, timeout_ns=timeout_ns)

    def range(self, msg_type, topic, key, t0, t1, by="commit", limit=1000):
        reply = self.request("range", topic, key, t0=t0, t1=t1, by=by, limit=limit)
        return Range(reply.status, [_result(msg_type, "ok", s) for s in reply.samples], reply.truncated, reply.lost, reply.error)

    def snapshot(self, objects, t, by="commit"):
        return self.request("snapshot", objects=[str(o) for o in objects], t0=t, by=by)

    def info(self, topic, key=""):
        return self.request("info", topic, key)

    def search(self, **criteria):
        return self.request("search", **criteria)

    def list(self):
        return self.request("list")

    def changes(self, after, **criteria):
        return self.request("changes", t0=after, **criteria)

    def wait_object(self, timeout_ns, **criteria):
        return self.request("wait_object", timeout_ns=timeout_ns, **criteria)

    def samples(self, msg_type, topic, key="", t0=0, t1=ALL_TIME[1], by="commit"):
        """Every sample of an object from t0 to t1 (exclusive), oldest first, a thousand per request."""
        while t0 < t1:
            page = self.range(msg_type, topic, key, t0, t1, by=by)
            if page.status not in ("ok", "partial"):
                if page.status == "error":
                    raise _cpm.Error(page.error)
                return
            for r in page.samples:
                yield r
            if not page.truncated or not page.samples:
                return
            last = page.samples[-1]
            t0 = (last.commit_ns if by == "commit" else last.data_ns) + 1

    def table(self, msg_type, topic, key="", t0=0, t1=ALL_TIME[1], by="commit"):
        """The object's samples as columns: commit_ns, data_ns and every field (nested ones as
        "pose.x"; sequences as lists), as numpy arrays where numpy is installed."""
        columns = {"commit_ns": [], "data_ns": []}
        for r in self.samples(msg_type, topic, key, t0, t1, by):
            columns["commit_ns"].append(r.commit_ns)
            columns["data_ns"].append(r.data_ns)
            for name, value in _flat(r.sample.to_dict()):
                columns.setdefault(name, []).append(value)
        try:
            import numpy
        except ImportError:
            return columns
        return {k: numpy.asarray(v) if v and not isinstance(v[0], (list, bytes)) else v for k, v in columns.items()}


def _flat(d, prefix=""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flat(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


def open_recording(path):
    """A finished run's recording (recording.db), answering every HistoryClient question from
    the file (read into memory once). cpm.Error names a file that is no recording."""
    return HistoryClient(_client=_cpm.HistoryClient.open_recording(str(path)))
