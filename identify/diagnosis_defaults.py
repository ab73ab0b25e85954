"""Defaults of the friction diagnosis (:mod:`identify.diagnosis`) that light modules need: the
``greybench diagnose`` option defaults, whose help must not import numba, scipy or the models."""
from __future__ import annotations

#: Held-out RMS torque a candidate must explain to be named, as a share of the held-out
#: residual's noise RMS (:func:`identify.diagnosis.noise_rms`) [-]. Null distribution measured on clean synthetic
#: records (LuGre plant, 0.02 Nm noise, UT train / test trajectory, 15 GA generations): the
#: best candidate's score over 30 seeds of 25 s records had its 99th percentile at 0.33 mNm
#: (max 0.34 mNm), i.e. 0.017 of the noise; 60 s records stayed below 0.0125. 0.1 is six
#: times that: a candidate is named only when it predicts a tenth of the noise RMS on data it
#: never saw.
SCORE_THRESHOLD = 0.1
