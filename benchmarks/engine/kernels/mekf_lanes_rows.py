"""A group's buffer in the MEKF's kernel in lanes: after the rows every
kernel in lanes has (:mod:`benchmarks.engine.kernels.lanes`), LANES numbers
a row (one a run), its own.

The filter: the bias estimate β̂, P (6x6, row-major), the filter's σ_v² and
σ_u. Each step's propagation
(:mod:`~benchmarks.engine.kernels.mekf_lanes_propagation`): |ω̂|, Φ's and
Q's five coefficients, the rotation vector turned through (ω̂ Δt, or an
update's δθ), its angle, cos(θ/2) and sin(θ/2)/θ, Φ's blocks A and B, Q's
blocks Q11 and Q12, the top three rows of Φ P.
"""
from __future__ import annotations

from benchmarks.engine.kernels import lanes

(BETA, P, NOISE, BIAS_RW, RATE, COEFFICIENTS, TURN, ANGLE, COS, HALF_SINC, A, B, Q11, Q12,
 FP, ROWS) = lanes.first_rows(lanes.OWN_ROWS, beta=3, P=36, noise=1, bias_rw=1, rate=1,
                              coefficients=5, turn=3, angle=1, cos=1, half_sinc=1, A=9, B=9,
                              Q11=9, Q12=9, FP=18)
