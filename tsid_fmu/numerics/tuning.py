"""The tuned constants of the search, its verdicts and its intervals, in one place.

Every module-level number that ``tsid_fmu/numerics/``, ``tsid_fmu/search/`` and
``tsid_fmu/uncertainty/`` decide by lives here, grouped by the module that reads it
(which imports it under the name it uses); each says what it decides and, where it
was measured, on what. ``docs/reference/tuning.md`` lists them all with their values
(``python -m tsid_fmu.numerics.tuning_page`` writes that page; a test keeps the two
alike), and ``tests/test_tuning.py`` fails where a module of those three packages
defines a number of its own.
"""

from __future__ import annotations

# -- tsid_fmu.numerics.fdstep --------------------------------------------------------------

SHARE = 100.0
"""A column's difference must be this many times its noise (1 % error)."""

MAX_STEP = 1e-2
"""Largest forward-difference step, in search coordinates (1 % of a first range)."""

POINTS = 4
"""Simulations of :func:`solver_noise` (beyond the point itself)."""

OVERFLOW = 1e150
"""Residuals above this are scaled before their differences are squared (their squares
would overflow past about 1e154)."""

# -- tsid_fmu.numerics.rank ----------------------------------------------------------------

UNSEEN = 1e-14
"""Share of the largest eigenvalue of ``J^T J`` below which a direction is unseen: a
singular value of the Jacobian at most ``sqrt(UNSEEN)`` = 1e-7 of the largest is one
the outputs do not depend on (:func:`tsid_fmu.uncertainty.intervals.seen_inverse`)."""

# -- tsid_fmu.numerics.space ---------------------------------------------------------------

FLOOR_BAND = 0.5
"""Decades above a log parameter's floor that :meth:`Space.floored` still counts as on it.

Half a decade: a value there is at most 0.3 % of the smallest first level, and one a
decade above the floor (two below the smallest level) is a value of its own, not the
floor.
"""

# -- tsid_fmu.search.local.adaptive --------------------------------------------------------

RESTART_SEPARATION = 0.15
"""A restart's start lies at least this far (in first ranges, along some parameter) from
every start and answer of the refinements before it."""

AGREE = 1e-4
"""Relative cost difference within which the refinement after the horizons reaches "the
same answer" as the search before them; it then needs no restart."""

# -- tsid_fmu.search.local.columns ---------------------------------------------------------

PARALLEL = 1e-2
"""Two Jacobian columns are taken as parallel where ``1 - |cos|`` of their angle is below
this. Measured on the SISO plant at law 3's answers (dev seeds 101 to 103), with relative
forward-difference steps: viscous friction and spring damping 1.7e-4 to 1.0e-3 (event
noise: their different steps shift different events; with steps matched to their sum,
4e-9 to 6e-8), every other pair 0.03 or more. A pair taken wrongly costs the runs of
:func:`~tsid_fmu.search.local.combined.combined_refinement`, whose answer is kept only where it
is lower."""

EXACT = 2.0 * UNSEEN
"""Two columns closer than this (``1 - |cos|``) are exactly parallel: the smallest
eigenvalue of their Gram matrix is then at most
:data:`~tsid_fmu.numerics.rank.UNSEEN` of the largest, so the direction along the
pair is one the outputs do not see at all, with no slope to follow (OpenModelica's
``Mass_Damper``: its three offsets and the force act only through their sum, ``1 - |cos|``
of 0 to 4e-16). The covariance reports it open; a refinement along it only wanders
(measured there: the force moved from 1 N to -8839 N for a gain of 4e-6 of the cost, 90
runs, and left an offset by its logarithmic floor, where the profiles then closed the
common scale of mass, damping and stiffness around a point away from the truth)."""

# -- tsid_fmu.search.local.combined --------------------------------------------------------

COMBINED_STEP = 1e-6
"""Relative forward-difference step of :func:`physical_jacobian` (the columns of the
SISO pair stayed parallel for steps from 1e-6 to 1e-2)."""

MATCHED = 1e-4
"""A round of :func:`matched_ratio` that moves the ratio by less than this fraction of
itself is its last."""

COMBINED_FTOL = 1e-4
"""SciPy's ``ftol`` for :func:`combined_refinement`: it stops where a step lowers the cost
by less than this fraction (SciPy's default, 1e-8, spent the budget of 80 runs on the
SISO pair for the last 0.01 %: dev seeds 101 and 102 were within 0.1 % of their end after
32 to 48 runs)."""

# -- tsid_fmu.search.local.problem ---------------------------------------------------------

FD_STEP = 1e-5
"""Forward-difference step in search coordinates (1e-5 of a first range's width), where
the FMU's own noise allows it (:mod:`tsid_fmu.numerics.fdstep` widens it where not).

Small enough for a sharply curved valley (a swinging pendulum's cost over seconds of
data: 1e-3 gave secants whose steps kept failing), large against the integrators' error
(the own Model Exchange solver's rtol is 1e-8)."""

FAILED = 1e10
"""Residual value given to every sample of a failed simulation (its cost is then huge), in
the refinement and in the refinement in combinations."""

PROBLEM_FTOL = XTOL = GTOL = 1e-8
"""SciPy's termination tolerances, as :func:`scipy.optimize.least_squares` names them."""

# -- tsid_fmu.search.structure.arrays ------------------------------------------------------

ARRAYS_ALPHA = 0.05
"""Significance level of the ANOVA F test that a discrete factor's effect must pass."""

MAX_ITERATIONS = 3
"""Most iterations of the mixed arrays (fewer where the study's limit is lower).

The arrays screen structure and parameters together; they do not take a structure to
its optimum. Far from the fit a discrete factor's levels' means measure how each
structure tolerates the Real parameters' wrong levels, not which structure fits
(measured on the SISO friction laws: the law was fixed at 1e7 to 2e8 times the optimum's
cost, the wrong one on two of three data sets, after 8 to 10 iterations of 27 runs;
``docs/dev/structure-diagnosis.md``). Every candidate is refined to its own optimum after
them (:mod:`tsid_fmu.search.structure.compare`), so iterations beyond the first few only cost
simulations."""

# -- tsid_fmu.search.structure.boundary ----------------------------------------------------

RELATIVE_STEP = 1e-6
"""Forward-difference step of a shared parameter, relative to its value."""

SPAN_STEP = 1e-4
"""Forward-difference step of an extra parameter, as a fraction of its first levels' range
(its value at the nesting point may be 0 or 1e-4: a step relative to it measures nothing)."""

# -- tsid_fmu.search.structure.compare -----------------------------------------------------

MAX_CANDIDATES = 8
"""Most candidate structures refined at the end."""

MAX_ALL = 6
"""Where the discrete factors' combinations are at most this many, every one of them is a
candidate (a fixed factor's other levels too, not only its runner-up)."""

# -- tsid_fmu.search.structure.nesting -----------------------------------------------------

REPRODUCE = 0.01
"""A richer structure nests a simpler one where its extra parameters reproduce the
simpler one's fitted outputs to within this fraction of one noise variance in total."""

NESTING_POINT = 0.01
"""A richer answer's extra parameters within this fraction of their first levels' range of
the values that make it a simpler structure are at the nesting point."""

FAR_BETTER = 0.5
"""A richer answer whose chi-square is below this fraction of a simpler one's is not at a
nesting point of that answer: there the richer structure is the simpler one, and fits
no better than the simpler one's optimum beyond what the model's non-smoothness gives
(measured on the SISO friction laws: a Stribeck answer at the Coulomb + viscous nesting
point, 0.2 % below). For such a pair an embedding of the simpler answer found earlier
shows the nesting, with no fit at the richer answer."""

# -- tsid_fmu.search.structure.optima ------------------------------------------------------

ACTIVE_STEP = 0.01
"""Step (in search coordinates: a fraction of the first levels' range) by which each Real
parameter is moved to see whether it changes the outputs in a structure."""

PATH_STEPS = 4
"""Steps of :func:`follow` from a richer answer to the simpler structure it nests."""

MAX_ROUNDS = 3
"""Most rounds of :func:`consistent` (each round re-checks the pairs that changed)."""

WARM_NFEV = 10
"""Simulations per (Real parameter + 1) of a refinement from warm starts and of a restart
(the study's own limit where lower). A candidate chosen from a warm start that stopped
short of an optimum gets a study of its own
(:func:`~tsid_fmu.search.structure.candidates.needs_own_study`); measured on the SISO friction
laws, warm refinements and restarts that ran to the default limit (30 per parameter +
1) spent 200 to 750 simulations per structure, most of them on structures the
comparison then rejected by 1e5 in BIC."""

# -- tsid_fmu.search.structure.selection ---------------------------------------------------

LRT_ALPHA = 0.05
"""A richer nested structure wins only where the likelihood-ratio test gives p below this."""

BIC_CLOSE = 2.0
"""BIC difference below which two structures (costs within noise) are indistinguishable."""

# -- tsid_fmu.search.taguchi.nextlevels ----------------------------------------------------

ROTATED_LEVELS = 3
"""Levels of rotated factors unless ``n_levels`` says otherwise: along principal axes the
surface is close to quadratic, and three levels (an L18 for five factors, an L9 for up
to four) give each factor's parabola for fewer runs than five levels (the MISO paper
identifies with three-level L9 arrays throughout)."""

MAX_HALF_WIDTH = 0.5
"""Largest half-width of a rotated factor, in search coordinates (the first levels of
every parameter span one unit)."""

GROWTH = 1.5
"""Most a rotated factor's half-width may exceed the extent of the decided box along
it: the curvature shapes the levels, the papers' cases still set their size."""

POSITIVE_MARGIN = 0.75
"""A rotated factor's levels may move a parameter searched in log10 by at most this
fraction of its value (so it stays positive, as its log10 coordinate guarantees)."""

# -- tsid_fmu.search.taguchi.stage ---------------------------------------------------------

RERUN_AFTER = 2
"""Iterations without a lower cost after which the next-best run is re-conducted."""

# -- tsid_fmu.search.verdict ---------------------------------------------------------------

GATE_RTOL = 1e-4
"""Largest decrease of the cost, relative to itself, that the local model may still
predict at an answer called stationary."""

MAX_TRIALS = 12
"""Fractions of a Gauss-Newton step a stationarity test simulates at most (1, 1/2, ...,
1/2**11)."""

POOR_FIT = 20.0
"""An answer whose cost exceeds the noise floor by this factor is a poor fit. On the
generalisation benchmark's dev seeds the optima of mismatched models sit at up to about
10 times the floor (strongly coloured noise far more: 311 times at AR(1) 0.86), local
minima at hundreds to thousands of times: a poor fit sends the search on, but it does
not change the verdict."""

# -- tsid_fmu.uncertainty.assess -----------------------------------------------------------

MISMATCH = 1.5
"""Residual RMS above this many times an output's noise estimate is reported as model
(or solver) mismatch."""

# -- tsid_fmu.uncertainty.bounds -----------------------------------------------------------

ON_BOUND = 1e-6
"""A value within this fraction of its first levels' span from a bound is on it."""

TOWARD_ZERO = 1e-2
"""A positive value below this fraction of its smallest first level, with ``min = 0``, is
on that bound: the search moves positive parameters in log10, where 0 lies at minus
infinity, so a value the data push to 0 stops some decades short of it."""

# -- tsid_fmu.uncertainty.discrepancy ------------------------------------------------------

DISCREPANCY_ALPHA = 0.001
"""Significance level of the constancy test: one false alarm in a thousand studies of
a correct model."""

SEGMENTS = 2
"""Segments each experiment's record is cut into for the constancy test."""

RANK = 1e-9
"""Eigenvalues of the scores' covariance below this share of the largest are dropped
(directions the data do not see, where the Jacobian holds only the FMU's noise)."""

# -- tsid_fmu.uncertainty.fidelity ---------------------------------------------------------

BIAS_LIMIT = 1.0
"""At the answer, a solver error that alone moves an estimate by more than this many
standard errors matters too (the 95 % intervals would no longer cover the truth 95 % of
the time)."""

REFERENCE_TOLERANCE = 1e-12
"""Relative tolerance of the Model Exchange reference, 100 times tighter than a study's
default (:class:`~tsid_fmu.study.schema.Method` ``tolerance``). FMPy's CVode takes this
times each state's nominal value (often 1) as the absolute tolerance, so a state of
micrometres needs a relative tolerance far below its noise; 1e-12 costs about 30 % more
time than 1e-10 on the bundled FMUs. A study with a tighter tolerance of its own gets a
reference 100 times tighter still (down to 1e-14)."""

CS_TOLERANCE = 1e-8
"""The tolerance a Co-Simulation study adopts for the FMU's own solver where the FMU's
default is too loose (:func:`choose_cs_tolerance`): the value ``cs_tolerance``'s
documentation proposes, two to four decades tighter than the 1e-4 to 1e-6 that
exporters commonly set as an FMU's default. Tighter costs every simulation of the study
time; this is adopted only where the check then passes, and the check at the answer
tells where it no longer does. Not tuned on a benchmark."""

CS_REFERENCE_TOLERANCE = 1e-10
"""The tolerance of the Co-Simulation reference: 100 times tighter than
:data:`CS_TOLERANCE`, as :data:`REFERENCE_TOLERANCE` is than the Model Exchange default
(and 100 times tighter than a study's own ``cs_tolerance``, down to 1e-14). An FMU whose
solver has a fixed step ignores it."""

FINER = 4
"""The Co-Simulation reference of a Co-Simulation-only FMU uses a communication step this
many times smaller than the study's."""

CONVERGES = 0.5
"""A Co-Simulation-only FMU converges as its step shrinks when the difference between
the steps ``h / FINER`` and ``h / FINER**2`` is at most this fraction of the difference
between ``h`` and ``h / FINER`` (worst output, in noise units). A consistent method of
order ``p`` gives ``FINER**-p`` (0.25 for explicit Euler), once in its asymptotic range;
an FMU that adds a fixed amount per step gives ``FINER`` (4)."""

# -- tsid_fmu.uncertainty.fidelity_record --------------------------------------------------

THRESHOLD = 0.2
"""A solver's RMS difference from the reference above this fraction of an output's
noise matters: the error is then a visible part of the residuals (it adds 0.2**2 = 4 % to
the least-squares cost at the true parameters, more above). A smaller error can still
move a parameter whose sensitivity resembles it, by up to ``ratio * sqrt(n)`` standard
errors over ``n`` samples; at the answer the check therefore also projects the error on
the sensitivities (:data:`~tsid_fmu.uncertainty.fidelity.BIAS_LIMIT`)."""

# -- tsid_fmu.uncertainty.intervals --------------------------------------------------------

LEVEL = 0.95
"""Confidence level of the intervals."""

Z95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution: :func:`quantile` for
many degrees of freedom."""

UNDETERMINED = 0.5
"""A combination whose standard error exceeds this many search units (half of a first
range) is *not determined* by the data."""

RATIO_GAIN = 4.0
"""A ratio of two parameters counts as determined when its relative standard error is
more than this many times smaller than each parameter's own (exactly this many: not)."""

# -- tsid_fmu.uncertainty.longrun ----------------------------------------------------------

LONGRUN_STEP = 1e-6
"""Finite-difference step of the AR coefficients in the delta method."""

# -- tsid_fmu.uncertainty.probe ------------------------------------------------------------

LOOSE = 2.0
"""Relative standard error (%) from which a combination is probed. JModelica's
``Simple2R1C_ic``, away from its optimum, gave its exact null direction (C against R1
and R2) 7 %: the FMU solver's noise in the central differences. The profile, not this
threshold, decides; a lower threshold only probes more (at most ``2 * REFITS + 1`` runs
each)."""

SPAN = 2.0
"""How many 95 % half-widths along the combination each probe goes."""

FLAT = 0.25
"""The largest profile rise, as a fraction of the 95 % threshold, of a direction found
not determined (a quadratic profile rises by ``SPAN**2`` = 4 thresholds there)."""

REFITS = 10
"""Most simulations per side: the point along the combination, then Gauss-Newton
re-fits. OpenModelica's ``Mass_Damper`` from ``tsid init`` (mass, stiffness and damping
scaled together, the spring's offsets following the force over stiffness) rose 5.1
after 3, 0.03 after 4 and 0 after 5; at most 3 called its exact symmetry determined."""

CHORD_COSINE = 0.9
"""The chord between a flat combination's two probes replaces its direction only within
about 25 degrees of it (a cosine of this or more): the solver's noise tilts a direction
by a few degrees; a chord further off comes from a probe clipped at a bound."""

GAIN = 0.01
"""A re-fit stops once a step lowers the cost by less than this share of the 95 %
threshold (as a profile's re-fit does, :data:`tsid_fmu.uncertainty.profile.CHORD_STEPS`)."""

MEMBER = 0.3
"""A parameter whose share of the combination's unit direction reaches this is in it."""

NEAR = 1e-3
"""Offset, in search units, of the point that gives the cost's level near the answer."""

# -- tsid_fmu.uncertainty.profile ----------------------------------------------------------

CHI2_95 = 3.841458820694124
"""95 % quantile of the chi-square distribution with one degree of freedom."""

CHORD_STEPS = 6
"""Most Gauss-Newton chord steps of the re-fit at each profile point; the re-fit stops
earlier once a step lowers the cost by less than 1 % of the threshold."""

MAX_DOUBLINGS = 10
"""Steps out from the answer, each twice the last, before an end is called open."""

MIN_STEP = 1e-3
"""Smallest first step, in search coordinates (0.1 % of a first range): a profile that
starts below what the simulations resolve would only measure their numerical noise."""

BISECTIONS = 3
"""Bisections of the bracket around an interval end."""

SECANT_MIN = 1e-3
"""Shortest step, in search coordinates, whose secant corrects a profile's Jacobian.
Over much shorter ones the residuals' change is rounding and solver noise: with none,
the chord's last, tiny steps wrecked the Jacobian of exact linear problems (four tests
of tests/test_interval_edges.py and test_coverage.py failed). On the SISO rig 1e-9 gave
the same ends as 1e-3."""

CHECKS = 3
"""Most checks of one side's outer bracket ends by a re-linearised re-fit."""

CHECK_STEP = 1e-6
"""Forward-difference step of a re-linearisation, in search coordinates. Short, to see
the smooth part of the residuals between events: on the SISO rig (dev seed 103, F_vm at
51.17) a check with steps of 2e-3 or 1e-4 found rises of 3.0 and 2.0 times the threshold
where one with 1e-6 found 0.35 times, and a full re-fit 0.26 times."""

RESOLUTION = MIN_STEP / 2**BISECTIONS
"""Shortest distance to an interval end the profile can tell, in search coordinates:
an end closer than the first step and every bisection of it is only known to lie
within this of the answer."""

# -- tsid_fmu.uncertainty.refits -----------------------------------------------------------

MAX_STEPS = 8
"""Most re-fit steps (simulations) per replicate."""

TOL = 1e-2
"""A replicate stops when a step lowers its cost by less than this many residual
variances (about ``sqrt(TOL)`` = 0.1 standard errors of a parameter)."""

INNER = 6
"""Gauss-Newton iterations on the model per step."""

# -- tsid_fmu.uncertainty.residuals --------------------------------------------------------

LAGS = 20
"""Lags of the Ljung-Box test."""

RESIDUALS_ALPHA = 0.01
"""Significance level below which residuals are called coloured."""

# -- tsid_fmu.uncertainty.sampled ----------------------------------------------------------

MIN_CONVERGED = 0.8
"""Share of the re-fits that must converge for the sampled intervals to be given."""

COLLAPSED = 1e-9
"""Relative width below which a sampled interval has collapsed onto one value."""

DEFAULT_REPLICATES = 100
"""Replicates (re-fits) when the study does not give ``uncertainty_replicates``."""

# -- tsid_fmu.uncertainty.sensitivity ------------------------------------------------------

SENSITIVITY_STEP = 2e-3
"""Half-step of the central differences in search coordinates: 0.2 % of each parameter's
first range (in decades for log parameters). Large enough to average over the small
discontinuities of models with dry friction or events, small enough that the
truncation error, of order ``STEP**2``, does not matter for a standard error."""
