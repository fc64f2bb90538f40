"""What the tests and the benchmarks share, shipped with the package (like
``numpy.testing``) so both import it as installed code.

* :mod:`~cdpr_pipeline.testing.independent_sim`: an independent simulator, a test oracle
  that deliberately shares no code with :mod:`cdpr_pipeline.sim` (``tests/test_layers.py``
  holds it to that);
* :mod:`~cdpr_pipeline.testing.draws`: the seeds of the tests' random draws (from the
  commit under test and the test's id; ``CDPR_TEST_SEED`` replays one);
* :mod:`~cdpr_pipeline.testing.lab_cases`: virtual-lab datasets with hidden effects and the
  diagnosis settings of the tests;
* :mod:`~cdpr_pipeline.testing.foreign_cases`: independent-simulator datasets diagnosed like
  a user's recording, graded against their truth (the detection and null-calibration
  studies).

Nothing else in the package imports this one.
"""
