"""Every lab message type as a Python class: fields as attributes, dict round trips, repr and
equality; every value checked against its IDL type with an error naming the field."""
import pytest

import cpm
from cpm import types as T
from cpm._idl import ENUMS, FIELDS

INT_RANGES = {"octet": (0, 255), "short": (-2**15, 2**15 - 1), "unsigned short": (0, 2**16 - 1), "long": (-2**31, 2**31 - 1),
              "unsigned long": (0, 2**32 - 1), "long long": (-2**63, 2**63 - 1), "unsigned long long": (0, 2**64 - 1)}


def value_of(t, seed):
    if t in FIELDS:
        return filled(t, seed)
    if t in ENUMS:
        return getattr(T, ENUMS[t][-1])
    if t in INT_RANGES:
        return INT_RANGES[t][1] - seed  # the top of the range: a narrowing would show
    if t in ("double", "float"):
        return seed + 0.25
    if t == "boolean":
        return True
    if t == "string":
        return f"text {seed} ü"
    raise AssertionError(f"no value for IDL type {t}")


def filled(name, seed=1):
    """A sample of `name` with no field at its default: a field lost anywhere would show."""
    s = getattr(T, name)()
    for i, (field, kind, t, bound) in enumerate(FIELDS[name]):
        k = seed + i
        if kind == "single":
            setattr(s, field, value_of(t, k))
        elif kind == "array":
            setattr(s, field, [value_of(t, k + j) for j in range(bound)])
        elif t == "octet":
            setattr(s, field, bytes([k % 256, 0, 255]))
        else:
            setattr(s, field, [value_of(t, k), value_of(t, k + 1)])
    return s


@pytest.mark.parametrize("name", sorted(FIELDS))
def test_every_type_round_trips_through_a_dict_and_compares_by_value(name):
    s = filled(name)
    assert getattr(T, name).from_dict(s.to_dict()) == s
    assert s != getattr(T, name)()
    assert repr(s).startswith(name + "(")
    assert list(s.to_dict()) == [f[0] for f in FIELDS[name]]


def test_nested_structs_change_in_place_and_keywords_fill_fields():
    s = T.VehicleState(vehicle_id=3, speed=0.5)
    s.pose.x = 1.5
    s.header.create_stamp.nanoseconds = 10
    assert (s.vehicle_id, s.speed, s.pose.x, s.header.create_stamp.nanoseconds) == (3, 0.5, 1.5, 10)
    cpm.stamp_message(s, 100, 20)
    assert (s.header.create_stamp.nanoseconds, s.header.valid_after_stamp.nanoseconds) == (100, 120)
    c = T.VehicleCommandTrajectory(trajectory_points=[T.TrajectoryPoint(px=1.0), T.TrajectoryPoint(px=2.0)])
    assert [p.px for p in c.trajectory_points] == [1.0, 2.0]
    f = T.CameraFrame(data=b"\x01\x02")
    assert f.data == b"\x01\x02"


INT_FIELDS = [(n, f, t) for n in sorted(FIELDS) for f, kind, t, _ in FIELDS[n] if kind == "single" and t in INT_RANGES]


@pytest.mark.parametrize("name,field,t", INT_FIELDS)
def test_an_integer_out_of_its_idl_range_is_a_value_error_naming_the_field(name, field, t):
    lo, hi = INT_RANGES[t]
    s = getattr(T, name)()
    for bad in (lo - 1, hi + 1):
        with pytest.raises(ValueError, match=f"{name}.{field}: {bad} is out of range for IDL {t}"):
            setattr(s, field, bad)
    setattr(s, field, hi)
    assert getattr(s, field) == hi


def test_wrong_types_are_type_errors_naming_the_field():
    with pytest.raises(TypeError, match="VehicleState.speed: expected a number, got str"):
        T.VehicleState(speed="fast")
    with pytest.raises(TypeError, match="VehicleState.vehicle_id: expected an integer"):
        T.VehicleState(vehicle_id=1.5)
    with pytest.raises(TypeError, match="VehicleState.is_real: expected True or False"):
        T.VehicleState(is_real=1)
    with pytest.raises(TypeError, match="VehicleState.pose: expected a Pose2D, got Point2D"):
        T.VehicleState(pose=T.Point2D())
    with pytest.raises(TypeError, match=r"VehicleCommandTrajectory.trajectory_points\[1\]: expected a TrajectoryPoint, got int"):
        T.VehicleCommandTrajectory(trajectory_points=[T.TrajectoryPoint(), 3])
    with pytest.raises(ValueError, match="ArucoMarker.corners: expected exactly 4 elements, got 3"):
        T.ArucoMarker(corners=[T.Point2D()] * 3)
    with pytest.raises(TypeError, match="VehicleState: no field 'sped'"):
        T.VehicleState(sped=1.0)
    with pytest.raises(TypeError, match="VehicleState.pose: no field 'z'"):
        T.VehicleState.from_dict({"pose": {"x": 1, "z": 2}})
    with pytest.raises(ValueError, match=r"VehicleStateList.active_vehicle_ids\[0\]: 4294967296 is out of range for IDL long"):
        T.VehicleStateList(active_vehicle_ids=[2**32])


def test_readers_and_writers_name_a_wrong_type_or_option():
    with pytest.raises(TypeError, match="cpm.Writer: no option 'relaible'"):
        cpm.Writer(T.VehicleState, "vehicleState", relaible=True)
    with pytest.raises(TypeError, match="is not a lab topic type"):
        cpm.Writer(T.Pose2D, "pose")
    with pytest.raises(TypeError, match="is not a lab keyed topic type"):
        cpm.MultiVehicleReader(T.Log, "log", [1])
    with pytest.raises(ValueError, match="vehicle id 0 is not 1..255"):
        cpm.MultiVehicleReader(T.VehicleState, "vehicleState", [0])


def test_the_stubs_name_every_public_name_of_the_package_and_its_compiled_module():
    """Editors complete from the stubs: every name the package exports and every public name of
    the compiled module is in them, with a signature where it is a function."""
    import ast
    import os
    folder = os.path.dirname(cpm.__file__)
    with open(os.path.join(folder, "_cpm.pyi"), encoding="utf-8") as f:
        tree = ast.parse(f.read())
    stubbed = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    stubbed |= {t.target.id for t in tree.body if isinstance(t, ast.AnnAssign)}
    with open(os.path.join(folder, "types.pyi"), encoding="utf-8") as f:
        typed = {n.name for n in ast.parse(f.read()).body if isinstance(n, ast.ClassDef)}
    missing = [n for n in dir(cpm._cpm) if not n.startswith("_") and n not in stubbed and n not in typed]
    assert missing == [], f"not in _cpm.pyi: {missing}"
    # The Timer's methods with their parameters, as pybind11 gives them.
    timer = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Timer")
    methods = {f.name: [a.arg for a in f.args.args] for f in timer.body if isinstance(f, ast.FunctionDef)}
    assert "start" in methods and "stop" in methods, methods
    functions = {f.name: f for f in tree.body if isinstance(f, ast.FunctionDef)}
    assert ast.unparse(functions["get_time_ns"].returns) == "int"
