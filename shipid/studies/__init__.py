"""Studies: thin users of the public API on particular data sets and papers.

* :mod:`shipid.studies.kvlcc2` -- hold-out validation on the measured MARIN KVLCC2 runs (SIMMAN 2008).

The paper set-ups that are part of a module's own API stay with it: the glider launch sweep
(:mod:`shipid.glider.study`, used by the glider optimiser), the optimal-control paper problems
(:mod:`shipid.control.scenarios`, named by ``shipid plan``) and the PSO paper scenario
(:func:`shipid.routing.pso.paper_scenario`, named by ``shipid route pso-paper``).
"""
