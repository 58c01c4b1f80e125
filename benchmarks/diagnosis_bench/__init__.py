"""The diagnosis benchmark: the discrepancy analysis judged, as a classifier is, on cases drawn over the records
users have rather than on the examples it was tuned on.

:mod:`.mechanisms` hides one physical mechanism per case with the generator's own code, :mod:`.cases` draws a case
from a seed (model, mechanism and size, rate, length, excitations, noise), :mod:`.truth` builds its records,
:mod:`.run` diagnoses them (one JSON row per case, resumable, on the project's execution backend), :mod:`.score`
turns the rows into the confusion matrix, rates per stratum, detection limits, parameter errors and the
calibration of the stated confidence, and :mod:`.page` writes docs/diagnosis-benchmark.md and its figure.
``piezotwin bench-diagnosis`` runs it; ``make bench-diagnosis`` the full set, CI a stratified sample.
"""
