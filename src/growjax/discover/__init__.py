"""Missing physics: where model and measurement disagree, which catalogue effect explains it, and how sure.

The workflow (`discover`), on the measured length L(t) of a set of one experiment (a larger set is discovered by its
joint fits: ``_set``'s procedure, one round):

1. **Base fit.** The base model's free parameters (default the yield pressure Y) are fitted by
   least squares, in the *superset* model that carries every candidate effect at zero (which is
   the base model exactly), so every later fit runs through the same compiled program (one per number of fitted
   coordinates). It starts from the
   given values and from 0.7 and 1.4 times them (real data can leave more than one minimum in Y), keeping
   the best, so that no candidate scores against a base stuck in a side minimum.
2. **Locate.** The residuals r = L_model − L_meas are summarised over time and by phase (growing,
   holding, retracting; pressure rising or falling) (:func:`locate`). The noise σ is estimated from
   successive differences of r (a smooth misfit barely enters them), and the misfit test asks whether
   the residuals carry more than that noise: a lag-1 autocorrelation z-score and the ratio RMSE/σ.
3. **Test each candidate.** Each effect parameter η is fitted jointly with the base parameters, starting from
   the base fit's values and from several starts of η (2, 6 and 20 % of its range's top; the misfit can have
   more than one minimum along an effect, e.g. one per alignment of a lag with the pulse period), keeping the
   best fit.
   Its score is the likelihood ratio 2ΔlogL = (RSS_base − RSS_k)/σ² of the nested models; under
   the null (effect absent, η on the boundary 0) it is distributed as ½χ²₀ + ½χ²₁, and the
   threshold is set so that the *family* of K candidates gives a false positive with probability
   ``false_positive_rate`` (Bonferroni). A Laplace estimate of the log Bayes factor against a uniform
   prior on the effect's physical range is reported beside it (``log_bayes_factor``).
4. **Confounding.** A candidate whose η correlates with a base parameter beyond
   ``confounding_correlation`` (0.99: the base parameter inflates its variance 50-fold) in the joint fit is
   reported ``confounded`` with that parameter if it clears the threshold, or if, with the base parameters
   held at their given values, it alone explains the data as well as refitting them does (within the
   threshold) while the given values themselves fit significantly worse: the effect and the base parameter
   trade one for the other. "Significantly" here allows for the fitted configuration's own error e against
   the reference (``model_error``): absorbed by a base shift it alone lowers the sum of squares by up to m·e²,
   so the effect must improve on the given values by more than the threshold plus m·e²/σ² (m samples; on
   clean reference-made data, 10 s at σ = 0.2 mm, the given Y fits worse by 2ΔlogL ≈ 9 through that error
   alone). Each base-held fit starts where its joint fit's linearisation puts the effect once the base
   parameters return to their given values (the effect taking over the base shift along their shared valley:
   :func:`_held_start`). A correlated candidate that clears the threshold with its magnitude *pinned*
   (its 90 % interval, the correlation's inflation included, within a factor ``PINNED_FACTOR`` of the
   estimate) is not confounded: refitting the base did not absorb it, and the data fix its size. Its
   correlation is still reported.
5. **Rivals.** When another candidate also clears the threshold and its 2ΔlogL falls short of the best's by
   less than the threshold, the data do not tell the two effects apart: neither is added, both are reported
   ``confounded`` (``rival_effects``), with the measurements that would separate them.
6. **Add and iterate.** The best candidate is added; the remaining ones are tested again on top of it
   (up to ``max_effects``). An effect is claimed only if, once added, the misfit test passes; if
   structure remains that no candidate removes, the answer is ``unexplained``; with no misfit and no
   candidate over the threshold, ``none``.

Under the default likelihood (``discrepancy="matern32"``, `growjax.calibration.discrepancy`) every 2ΔlogL above
is a difference of profile log-likelihoods under a smooth discrepancy plus (possibly correlated) sensor noise,
with the rig's tolerances marginalised (`growjax.calibration.tolerance`, sensitivities at the base fit); the misfit
test becomes the discrepancy's significance against white noise, the base-held trade of step 4 counts
only where the misfit at the start is structured and material, and the allowance m·e²/σ² of step 4 becomes
its counterpart under that likelihood, tr(K⁻¹K_e) (K the residuals' covariance, K_e the drift's): a
discrepancy that already takes slow structure leaves the fitted configuration's drift less to buy.

Effect parameters are moved in u with η = s·softplus(u) (η ≥ 0) or η = s·u for effects whose range allows both signs;
s is a tenth of the range's upper end. Every fit is bounded to the physical ranges (η to its effect's, above a
thousandth of its top, ``ETA_FLOOR``; the base parameters to theirs): a wrong candidate that would climb past its
range to absorb a misfit stops at the edge (``at_range_edge`` in the evidence), where its runs are also the slowest.
Intervals on η are Gauss–Newton (delta method) at σ, clipped to the physical range. A fit stops once its steps move
neither 2ΔlogL by ``LR_RESOLUTION`` (σ estimated from the data's second differences) nor its cost by
``COST_NOISE`` of itself, the fast configuration's own noise: below that its trial points only wander
(`growjax.calibration.levenberg_marquardt`).

The package: the candidate problem and its fits (``_candidates``, ``_fitting``), scoring (``_scoring``), the
decision (``_decision``), the report (``_report``), the workflow that runs them on one experiment (``_workflow``), the
set's joint fits (``_set``) and the entry that takes a set to one or the other (``_entry``).
"""

from growjax.model import effects as fx

from ._candidates import (
    BASE_START_FACTORS,
    COST_NOISE,
    ETA_FLOOR,
    START_FRACTIONS,
    Z90,
    CandidateFit,
    Candidates,
    candidate_parameter,
    fit_model,
    linearised,
    make_candidates,
)
from ._entry import discover
from ._fitting import LR_RESOLUTION, Fitter
from ._report import PHASES, DiscoveryResult, locate, phases, summary_text
from ._scoring import (
    MATERIAL_MISFIT,
    PINNED_FACTOR,
    STRUCTURE_THRESHOLD,
    Scorer,
    is_pinned,
    misfit_test,
    noise_from_differences,
    score_candidate,
    score_round,
)
from ._set import SetDiscoveryResult, set_summary_text

__all__ = [
    "BASE_START_FACTORS",
    "COST_NOISE",
    "ETA_FLOOR",
    "LR_RESOLUTION",
    "MATERIAL_MISFIT",
    "PHASES",
    "PINNED_FACTOR",
    "START_FRACTIONS",
    "STRUCTURE_THRESHOLD",
    "Z90",
    "CandidateFit",
    "Candidates",
    "DiscoveryResult",
    "Fitter",
    "Scorer",
    "SetDiscoveryResult",
    "candidate_parameter",
    "discover",
    "fit_model",
    "fx",
    "is_pinned",
    "linearised",
    "locate",
    "make_candidates",
    "misfit_test",
    "noise_from_differences",
    "phases",
    "score_candidate",
    "score_round",
    "set_summary_text",
    "summary_text",
]
