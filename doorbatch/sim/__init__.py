"""doorbatch's simulator: worlds with hinged doors, scenarios, sensors, and logs with ground truth.

Library entry points: :func:`doorbatch.sim.simulate.simulate` (messages, no I/O) and
:func:`doorbatch.sim.simulate.run_simulation` (log + truth files). See ``docs/simulator.md``.
"""
