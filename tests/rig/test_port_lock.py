from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from core.errors import DeviceError
from rig.port_lock import port_lock
from rig.pose import RigPose
from sim.simulated_rig import SimulatedRig


def test_a_second_program_on_a_rig_is_refused_before_a_byte() -> None:
    with SimulatedRig() as simulated:
        with simulated.rig(camera=False) as first:
            first.move_to(RigPose(90.0, 30.0, 200.0, 60.0))
            before = simulated.gantry.machine_position()
            second = simulated.rig(camera=False)
            with pytest.raises(DeviceError) as refused:
                second.connect()
            message = str(refused.value)
            assert "is in use by process" in message and str(os.getpid()) in message
            assert "one program at a time" in message
            # Nothing reached the devices: the first still drives them, where it left them.
            assert simulated.gantry.machine_position() == before
            assert first.pose().light_azimuth_deg == pytest.approx(200.0, abs=0.3)
        # Released with the first: the next program connects.
        with simulated.rig(camera=False) as third:
            assert third.pose().light_inclination_deg == pytest.approx(60.0, abs=0.3)


def test_a_killed_holder_leaves_the_port_free() -> None:
    port = "/dev/rig-port-lock-test-" + str(os.getpid())
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time
            from rig.port_lock import port_lock
            lock = port_lock({port!r})
            lock.acquire()
            print("held", flush=True)
            time.sleep(600)
        """)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(DeviceError, match=f"process {holder.pid}"):
            port_lock(port).acquire()
    finally:
        holder.kill()
        holder.wait()
        if holder.stdout is not None:
            holder.stdout.close()
    lock = port_lock(port)
    lock.acquire()
    assert lock.held
    lock.release()
