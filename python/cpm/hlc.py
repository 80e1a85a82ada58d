"""cpm_lab's high-level-controller contract in Python:

    import sys, cpm
    cpm.init(sys.argv)                      # cpm lab run gives --dds_domain (the controller's own)
    out = cpm.Writer(cpm.types.VehicleCommandTrajectory, "vehicleCommandTrajectory")
    hlc = cpm.hlc.Communicator([1, 2])
    def step(state_list):                   # a cpm.types.VehicleStateList
        ...; out.write(command)             # stamped with state_list.t_now
    hlc.on_each_timestep(step)
    hlc.start()                             # until the lab stops it, stop() or Ctrl-C

A step still running when the next list comes is cancelled (on_cancel_timestep is called) and
the new list is not run; an exception in a step is logged with its traceback, the step counted
as failed, and the controller goes on.
"""
from . import _cpm


class Communicator:
    def __init__(self, vehicle_ids, participant=None):
        ids = list(vehicle_ids)
        for i in ids:
            if not isinstance(i, int) or isinstance(i, bool) or not 1 <= i <= 255:
                raise ValueError(f"cpm.hlc.Communicator: vehicle id {i!r} is not 1..255")
        self._c = _cpm.HlcCommunicator(ids, participant)

    def on_first_timestep(self, fn):
        self._c.on_first_timestep(fn)

    def on_each_timestep(self, fn):
        self._c.on_each_timestep(fn)

    def on_cancel_timestep(self, fn):
        self._c.on_cancel_timestep(fn)

    def on_stop(self, fn):
        self._c.on_stop(fn)

    def start(self):
        self._c.start()

    def stop(self):
        self._c.stop()

    vehicle_ids = property(lambda self: self._c.vehicle_ids)
    steps = property(lambda self: self._c.steps)
    cancelled_steps = property(lambda self: self._c.cancelled_steps)
    failed_steps = property(lambda self: self._c.failed_steps)
