"""Studies that chose and judge shipid's defaults, run from a source checkout (not installed).

* :mod:`studies.kvlcc2` -- hold-out validation on the measured MARIN KVLCC2 runs (SIMMAN 2008) and the
  leave-one-run-out rule that chose the fit recipe's defaults.
* :mod:`studies.esso_osaka` -- the Esso Osaka 3 m model's outdoor runs (wind, current, low speed): the
  leave-one-run-out study behind the ``lowspeed`` recipe defaults (``python -m studies.esso_osaka``).
* :mod:`studies.coverage` -- replicate study of how often the identifier's 95 % intervals contain the truth.

Each is a thin user of the public API.  Their tests are in ``studies/tests/`` (part of the default test run).
The paper set-ups that are part of a module's own API stay with it: the glider launch sweep
(:mod:`shipid.glider.study`), the optimal-control paper problems (:mod:`shipid.control.scenarios`) and the
PSO paper scenario (:func:`shipid.routing.pso.paper_scenario`).
"""
