"""The lab's message types (from the IDL), each a class with the IDL's fields as attributes:

    from cpm.types import VehicleState
    s = VehicleState(vehicle_id=3, speed=0.5)
    s.pose.x = 1.0                                  # nested structs are changed in place
    s.header.create_stamp.nanoseconds = 10
    VehicleState.from_dict(s.to_dict()) == s        # True

A sequence field is read as a new list: assign a list to change it (s.points = [...]); a
sequence of octets is bytes. A value out of its IDL type's range raises ValueError, a value of
the wrong type TypeError, both naming the field.
"""
from . import _cpm
from ._idl import ENUMS, FIELDS, KEYED, TOPIC_TYPES

__all__ = sorted(FIELDS) + sorted(ENUMS) + [v for vs in ENUMS.values() for v in vs] + ["TOPIC_TYPES", "KEYED"]


def _is_struct(t):
    return t in FIELDS


def _value_to_plain(v, kind, t):
    if kind == "single":
        if _is_struct(t):
            return v.to_dict()
        if t in ENUMS:
            return int(v)
        return v
    if t == "octet" and kind == "sequence":
        return list(v)
    return [x.to_dict() if _is_struct(t) else (int(x) if t in ENUMS else x) for x in v]


def _value_from_plain(v, kind, t, where):
    if kind == "single":
        return globals()[t].from_dict(v, where) if _is_struct(t) else v
    if not isinstance(v, (list, tuple, bytes, bytearray)):
        raise TypeError(f"{where}: expected a list, got {type(v).__name__}")
    if t == "octet" and kind == "sequence":
        return bytes(v) if isinstance(v, (bytes, bytearray)) else v
    return [globals()[t].from_dict(x, f"{where}[{i}]") if _is_struct(t) else x for i, x in enumerate(v)]


def _make(name):
    cls = getattr(_cpm, name)
    fields = FIELDS[name]
    names = [f[0] for f in fields]
    base_init = cls.__init__

    def __init__(self, **values):
        base_init(self)
        for k, v in values.items():
            if k not in names:
                raise TypeError(f"{name}: no field {k!r} (fields: {', '.join(names)})")
            setattr(self, k, v)

    def to_dict(self):
        """The fields as plain values (nested types as dicts), in IDL order."""
        return {f: _value_to_plain(getattr(self, f), kind, t) for f, kind, t, _ in fields}

    def from_dict(klass, d, where=None):
        """A new sample from to_dict()'s shape; a missing field keeps its default, an unknown
        one is a TypeError naming it."""
        where = where or klass.__name__
        if not isinstance(d, dict):
            raise TypeError(f"{where}: expected a dict, got {type(d).__name__}")
        out = klass()
        for k, v in d.items():
            spec = next((f for f in fields if f[0] == k), None)
            if spec is None:
                raise TypeError(f"{where}: no field {k!r} (fields: {', '.join(names)})")
            try:
                setattr(out, k, _value_from_plain(v, spec[1], spec[2], f"{where}.{k}"))
            except (TypeError, ValueError) as e:
                if str(e).startswith(where):
                    raise
                raise type(e)(f"{where}.{k}: {e}") from None
        return out

    def __repr__(self):
        return f"{name}(" + ", ".join(f"{f}={getattr(self, f)!r}" for f in names) + ")"

    def __eq__(self, other):
        return type(other) is type(self) and self.to_dict() == other.to_dict()

    cls.__init__ = __init__
    cls.to_dict = to_dict
    cls.from_dict = classmethod(from_dict)
    cls.__repr__ = __repr__
    cls.__eq__ = __eq__
    cls.__hash__ = None
    cls.__fields__ = tuple(names)
    return cls


for _name in FIELDS:
    globals()[_name] = _make(_name)
for _name, _values in ENUMS.items():
    globals()[_name] = getattr(_cpm, _name)
    for _value in _values:  # as in C++: ParameterType_Double
        globals()[_value] = getattr(globals()[_name], _value)
del _name, _values, _value
