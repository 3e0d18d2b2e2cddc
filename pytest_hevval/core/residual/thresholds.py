"""The diagnosis's fixed settings: materiality, the minimum share of a finding, the tests that
set a channel apart as a response, the time scales, and the names of the candidate kinds.

One room for every number the diagnosis judges by, so that the rules read together and each
other room names them rather than repeating them; each is explained where it is defined and
in ``docs/diagnosis.md``."""

from __future__ import annotations

#: A gain error smaller than this (relative) is not material, however significant.
GAIN_MATERIALITY = 0.005
#: An offset smaller than this fraction of the reference range is not material.
OFFSET_MATERIALITY = 0.005
#: A candidate must raise the explained variance by at least this much to be selected.
MIN_EXPLAINED_INCREASE = 0.005
#: A finding is relevant when fixing it alone removes at least this share of the residual's
#: mean square. 5 % lowers the RMS error by 2.5 % (√0.95): anything smaller cannot move λ4 by
#: more than a fortieth of its distance to 1, so it is listed as minor rather than as a cause.
MIN_SHARE = 0.05
#: A channel is a response (a consequence of what the model reproduces) when the simulated
#: signal explains at least this share of its variance ...
RESPONSE_MIN_R2 = 0.1
#: ... and the residual adds less than this fraction of that share on top of it, plus the
#: fraction a response to the measured signal gets from the residual anyway: one that moves
#: with the simulated part and the residual alike gains about var(r) / var(sim) of what the
#: simulation explains. A missing load moves with the residual only.
RESPONSE_RESIDUAL_RATIO = 0.25
#: A channel is an echo of the scored signal (an instrument of it, its derivative or its
#: integral) when, on block means of :data:`SLOW_SCALE_S`, the measured signal explains at least
#: this share of its variance (instrument, derivative) ...
ECHO_MIN_R2 = 0.8
#: ... or this share of the variance of its increments (integral: a state of charge) ...
ECHO_INCREMENT_MIN_R2 = 0.5
#: ... and the simulated signal explains at least this fraction of that: a missing load that
#: makes most of the measured signal is explained by it too, but not by the simulation.
ECHO_SIMULATED_RATIO = 0.5
#: A channel is an echo, too, when the measured signal as a whole explains at least this share
#: of its variance on those block means ...
ECHO_WHOLE_MIN_R2 = 0.25
#: ... and at least this fraction of what its two parts (the simulated signal and the residual,
#: with coefficients of their own) explain: a response to the measured power (a battery that
#: warms with the current, a state of charge's rate) weighs both parts alike, while a missing
#: load moves with the residual only.
ECHO_WHOLE_RATIO = 0.7
#: A channel whose cross-correlation with the measured signal peaks with the channel ahead by
#: at least RESPONSE_MIN_LEAD_S, within ±RESPONSE_LEAD_WINDOW_S, is treated as an input (the
#: driver acts, then the power follows), however well the measured signal explains it. A
#: shorter lead is within the timing jitter of CAN logging (frames at 10–100 Hz) and says
#: nothing about direction.
RESPONSE_LEAD_WINDOW_S = 2.0
RESPONSE_MIN_LEAD_S = 0.2
#: Windows over which the diagnosis says where the residual concentrates.
LOCAL_WINDOW_S = 30.0
#: Candidates whose series correlate at least this strongly (either sign) measure the same
#: thing: a heater's current, its power on two buses and its requested power are one effect.
GROUP_MIN_CORRELATION = 0.9
#: Besides the regression grid, every candidate is also tested on block means of this length.
#: A missing load acts over tens of seconds to minutes, while most of a model's 10 Hz residual
#: is its own fast dynamics error; pre-whitening that residual is nearly a difference filter
#: and removes the slow variation the load lives in. Block means of 10 s keep it.
SLOW_SCALE_S = 10.0
#: The slow scale is used only when the record holds at least this many of its blocks.
MIN_SLOW_BLOCKS = 20
#: Two effects are interchangeable on a record when what they explain in common is at least
#: this fraction of what the smaller of the two explains alone; the smaller one is then no
#: finding of its own (a gain and an offset can mimic a slowly varying load, a warming
#: battery can mimic a heater that is turned down).
INTERCHANGEABLE_OVERLAP = 0.5
#: The characteristics the diagnosis predicts after a fix.
PREDICTED_CHARACTERISTICS: tuple[str, ...] = ("mae", "rms")
#: Ljung-Box lags, in samples of the (possibly decimated) regression grid.
LJUNG_BOX_LAGS: tuple[int, ...] = (10, 20)

# A standardised candidate whose variance left after projecting out the ones already kept is
# below this fraction is a linear combination of them (|multiple correlation| > 0.999 999 5).
_COLLINEAR = 1e-6
_DEFAULT_MAX_LAG_S = 10.0
_KINDS: tuple[str, ...] = ("declared", "channel", "derivative", "lag", "gain", "offset")
#: The generic terms, which describe the simulated signal itself rather than name a cause.
GENERIC_KINDS: tuple[str, ...] = ("lag", "gain", "offset")
# Which member names a group when members explain about as much: the spec's own expression
# (the user's words), then a logged channel, then a derivative.
_NAMING_PREFERENCE = {"declared": 0, "channel": 1, "derivative": 2}
_NAMING_TOLERANCE = 0.05
# A member in the scored signal's own dimension names its group when it explains at least this
# fraction of what the best member does.
_DIMENSION_NAMING_SHARE = 0.5
