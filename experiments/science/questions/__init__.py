"""The questions a study answers (``dfrl paper``): each one primary measure, a contrast
against a control that cannot learn what is asked, an interval, Holm's correction within the
question's family and the power for the smallest effect that matters.

:mod:`.evaluations` (the data: ``evaluations.csv``), :mod:`.measures` (per-seed values),
:mod:`.catalogue` (the questions and their rows), :mod:`.contrast` (a paired contrast, its
verdict and power: scipy and statsmodels), :mod:`.answers` (judge them all) and
:mod:`.report` (``report.md``'s section, ``questions.csv``, ``contrasts_by_seed.csv``).
"""
