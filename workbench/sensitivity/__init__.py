"""Sensitivity of the identified parameters to the identification settings.

:mod:`~workbench.sensitivity.design` (factors, levels, designs, seeds),
:mod:`~workbench.sensitivity.run` (tasks and executors), :mod:`~workbench.sensitivity.analysis`
(effects, Monte Carlo uncertainty, verdicts, statements) and
:mod:`~workbench.sensitivity.study` (:func:`run_sensitivity`, the entry point).
"""
