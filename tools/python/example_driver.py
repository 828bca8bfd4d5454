#!/usr/bin/env python3
"""An example actuator driver in Python: each joint a rotor of inertia `J` with viscous
damping `b`, `J q'' = tau - b q'`, the torque saturated at the robot's effort limit and
held over the period (exact integration of the linear ODE for constant torque).

Started by `microrobot run` with, in the pipeline config,
    [actuator]
    command = [".../python", "tools/python/example_driver.py"]
it takes instance, rate, lockstep, watchdog and robot from the supervisor's environment
(MICROROBOT_CONFIG etc.); tools/python/microrobot_driver.py does the bus side.
"""

import argparse
import math
import sys
import time

from microrobot_driver import Driver, DriverConfig


class DampedInertiaArm(Driver):
    def __init__(self, cfg, inertia, damping):
        super().__init__(cfg)
        self.J, self.b = inertia, damping
        self.hold_inertia = inertia          # gains of the driver's own hold law
        self.q = list(cfg.initial_q)         # [actuator.sim]'s start, or the resume state
        self.qd = list(cfg.initial_qd)
        self.tau = [0.0] * self.dof

    def read(self):
        return self.q, self.qd, self.tau

    def write(self, tau, period):
        saturated = False
        for i in range(self.dof):
            lim = self.cfg.effort[i]
            t = min(max(tau[i], -lim), lim)
            saturated |= t != tau[i]
            # v(T) = v_inf + (v0 - v_inf) e^(-bT/J), v_inf = t/b; q integrates it.
            a = self.b / self.J
            e = math.exp(-a * period)
            v_inf = t / self.b
            self.q[i] += v_inf * period + (self.qd[i] - v_inf) * (1.0 - e) / a
            self.qd[i] = v_inf + (self.qd[i] - v_inf) * e
            self.tau[i] = t
        return saturated


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # J above the seed arm's own joint inertias (~0.1-0.3 kg m^2): the dynamics' feedback,
    # computed for the seed arm, then has less loop gain on this plant, not more, and
    # stays stable when the driver is late (J = 0.05 overshot by > 1 rad after stalls).
    p.add_argument("--inertia", type=float, default=0.3, help="J per joint, kg m^2 (0.3)")
    p.add_argument("--damping", type=float, default=0.5, help="b per joint, N m s/rad (0.5)")
    p.add_argument("--start-delay", type=float, default=0.0, metavar="S",
                   help="sleep this long before opening any port (a slow drive bus)")
    a = p.parse_args(argv)
    if a.start_delay > 0:
        time.sleep(a.start_delay)
    return DampedInertiaArm(DriverConfig(), a.inertia, a.damping).run()


if __name__ == "__main__":
    sys.exit(main())
