"""The strain solve's tuned constants, in one place, each with the reason for its value.

Importable without Taichi (the settings read it before ``cloth.backend.init``). The
measurements behind these values are in docs/history/ (the solver's change log) and the
current pages of docs/speed/.
"""

# settings strain.solve: "fast" stops a projection once the limits hold; "exact" solves it to
# the minimiser (active-set Newton model and a stationarity stop).
SOLVES = ("fast", "exact")

# AL rounds per projection (settings strain.rounds): a cap for stalled solves; converged ones
# take 2-8 rounds, and 50 ran out once in 300 remeshed svd frames where 100 never did.
AL_ROUNDS = 100

# "exact": the stationarity tolerance as a velocity (m/s): the Newton step at the answer moves
# no vertex by more than this x h (1 cm/s is 0.33 mm a step at 30 Hz, edges are 3-4 cm).
KKT_VELOCITY = 1e-2

# mapping: width (in eta1^2 - eta2^2) of the closure of its feasible set at isotropy, where the
# paper's constraint depends on an arbitrary principal frame (docs/method.md §3.3). 0.01 let the
# tshirt's worst projection converge in 13 rounds, where 0 did not converge in 200.
MAPPING_ISO = 0.01

# Initial AL penalty x the implicit metric's mean diagonal: a stiff start lets the warm
# multipliers end a resting solve in one round (1e3 rested hanging res 9 at 2e-9 J, 1e2 never).
MU_SCALE = 1e3
# "exact": its Newton matrix is the Hessian, so it needs no stiff penalty to keep steps short;
# a soft one lets the line search cross a constraint's kink cheaply.
ACTIVE_SET_MU = 1e-2
MU_GROW, MU_MAX_SCALE = 4.0, 1e6          # penalty x MU_GROW per round, capped at MU_MAX_SCALE

# Constraints within this strain of their band already enter the "fast" Newton matrix; for
# a band end nearer to rest than that (distance w < ACTIVE_MARGIN) within w^2 / ACTIVE_MARGIN
# (the end nearest to rest is where a resting cloth's faces sit closest to a bound): with
# a measured woven's +-0.57 % (a denim) a 1e-2 margin took every face into the matrix, its
# penalty stiffened every motion, and a Cusick skirt starting from rest froze where it began
# (DC 0.99; with margins of 4e-3 and 2.8e-3 it draped, 0.888, as the exact solve, 0.885;
# 5.7e-3 froze). Wider bands keep 1e-2 (with 2.5e-3 on the +-1 % warp band of hanging, the
# binding map turned to a scattered checkerboard that changed from run to run).
ACTIVE_MARGIN = 1e-2
# A near constraint's weight in that matrix rises as this power of its closeness to its band
# (0 at the margin's edge, 1 at the band; al.near_weight). The weight multiplies the penalty,
# 1e3 x the metric, so with a linear ramp a face a tenth of the way in still stiffened the
# model 100-fold: a cloth whose faces all sit inside the margin moved only isometrically.
# Measured (2-core AMD EPYC): a Cusick skirt of wool suiting (bands +-0.94 %, margin 8.9e-3)
# kept 0.4 % of a substep's fall where the exact solve keeps 40 %, and froze flat (DC 0.98
# at 0.5 and 0.8 cm; squared, still 0.98); cubed it drapes (0.69, 0.63; membrane only 0.67).
# To the fourth power a resting svd sheet kept 5e-6 J (hanging at resolution 9; it rests below
# 1e-6 J cubed). docs/fabrics.md, docs/speed/solve_cost.md.
NEAR_POWER = 3
# PCG relative residual per Newton step: 0.1 needs as many Newton steps as 1e-3 at half the work.
CG_RTOL = 0.1
# A round's inner loop stops once |grad L_A| fell below this fraction of its first value:
# the rounds are set by the multiplier updates, and 0.3 ran res 46 in 72 instead of 119 ms.
INNER_RTOL = 0.3

# Block-Jacobi PCG iterations per Newton step at 1000 faces, x sqrt(faces / 1000) above
# (corrections travel across the cloth): fewer leave the resting cloth shimmering.
CG_BUDGET = {"mapping": 15, "svd": 25, "warp-weft": 25}
# The factor preconditioner (factor_precond.py) up to this many faces, the multigrid above:
# the factor's serial triangular solves and factorisation grow faster than the mesh.
FACTOR_MAX_FACES = 2000
# "exact": the factor up to this many faces. The exact solve stops on its Newton step's
# length, which the multigrid's short PCG underestimates where the membrane is stiff (its
# translation aggregates cannot bend without stretching): on a 0.5 cm Cusick skirt of cotton
# shirting (6.4k faces) 12 iterations left 89 % of a Newton step with the multigrid, 7 % with
# the factor. The factor was also the faster exact solve on hanging at 4k faces (1.9 against
# 2.9 s a frame), about even at 16k (docs/speed/solve_cost.md).
EXACT_FACTOR_MAX_FACES = 10000
# PCG iterations with the factor: FACTOR_CG_WORK / faces clipped to [FACTOR_CG, FACTOR_CG_MAX]
# (an iteration costs ~ the faces, so small meshes afford more; 6 at 1152 faces rested best).
FACTOR_CG, FACTOR_CG_MAX, FACTOR_CG_WORK = 6, 20, 6000
# PCG iterations with the multigrid, one Newton step of them per AL round (up to MAX_NEWTON
# past LATE_ROUND, below). A short PCG finds the stiff (stretching) part of a step and little
# of its soft (bending, isometric) part, and a projection that ends feasible in its first round
# keeps what it found: a creeping Cusick skirt (denim, 0.5 cm, mapping) kept 5 % of a substep's
# fall with 2 steps of 4 iterations, 22 % with 1 of 8, where exactly solved Newton steps keep
# 74 % (the exact projection 83 %), and froze flat (DC 0.97; 0.90 with 12, as at 1 cm). One
# step of 12 is also no slower than two of 4 (8 for warp-weft) on a hanging sheet at 4k-65k
# faces (docs/speed/solve_cost.md).
MULTIGRID_CG, MULTIGRID_NEWTON = 12, 1
# A projection still running after LATE_ROUND rounds takes up to MAX_NEWTON Newton steps a
# round with the multigrid (a round ends sooner once its inner stop is met), and one that ends
# unconverged is solved again from its start with MAX_NEWTON steps in every round
# (solver._solve_al_with_fallback). Why: one step may not minimise a round's function far
# enough for its multiplier update; on svd's pulled sheet (pull, resolution 35 and 50, most
# faces at a band) the rounds then piled up to the budget and the sheet stretched 60 % past
# its limit. Five steps in every round would make a resting svd sheet (3-6 rounds a frame)
# 1.6-1.9x slower. docs/speed/solve_cost.md.
LATE_ROUND = 10
# Newton steps per AL round: block Jacobi 5 (3 shimmered), the factor 4 (finds most of the
# step per solve).
MAX_NEWTON, FACTOR_NEWTON = 5, 4
# "exact" in the kernels: its step predicts the active set from the PCG's answer, so the PCG
# runs tighter and a round takes more steps (with the fast settings 2 of 8 frames stalled).
PDAS_CG_RTOL, PDAS_NEWTON = 1e-2, 10

# The projection starts each vertex moved on at its last velocity, in full from 4 x this speed
# (m/s), not at all below it: from where the vertices were, a landing sheet was held in the air;
# moved on at every speed, the resting cloth jittered.
SETTLE_SPEED = 0.1

# Under contacts the fast solve's PCG is preconditioned by the factor of A (as without them)
# only while the cloth rests: the root mean square of its vertices' last velocities below this
# (m/s), and until it rises past twice this (``StrainLimiter._update_resting``). Through a
# landing the factor's fast answers kept none of the sheet's motion (docs/speed/drape_depth.md);
# the resting drape's speeds are 0.007-0.013 m/s, its landing's 0.1-1.4, its settling's
# 0.02-0.1.
RESTING_SPEED = 0.02
