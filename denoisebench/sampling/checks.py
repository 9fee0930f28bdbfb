"""No sampler can bias a score unseen: the convergence check run for every built-in and by ``check-plugin --sampler``.

:func:`convergence_check` runs a sampler on :func:`~denoisebench.sampling.synthetic.check_frame`
(known truth; skewed, heteroscedastic noise; edges; a dark corner) at rising mean spp budgets,
several seeds each, and compares its image with the truth. It passes when

* **the error falls**: the relative MSE ``mean((p − t)² / (t² + 0.01))`` (docs/architecture.md's epsilon) at the
  largest budget is at most :data:`MAX_ERROR_RATIO` of the one at the smallest (an unbiased
  estimator at 16× the samples has 1/16; a sampler stuck on a biased image stays near 1);
* **the mean converges to the truth**: the relative bias ``mean((p − t) / (t + 0.01))`` over the
  pixels and seeds at the largest budget is within ``4`` standard errors (from the truth's known
  per-sample variance at the sampler's own counts) plus :data:`BIAS_SLACK`;
* **every pixel has a sample** at the largest budget, and no budget is exceeded (the harness cannot
  let it be; checked anyway).

Notes
-----
* Adaptive sampling on noisy estimates is consistent but not unbiased: the allocation and any
  stopping rule read the same samples whose mean is scored (a pixel whose first samples came out low
  looks converged to ``ci_stop``, and has a large relative error to ``hachisuka2008``). On this frame
  the built-ins' relative bias is about 1 % at 4-16 spp and below 0.3 % at 64 spp; :data:`BIAS_SLACK`
  allows 0.5 % at the largest budget, far below what a sampler that skips or drops samples shows.
* Under-spending is reported (``spent``), not failed: a stopping rule may legitimately stop early.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from denoisebench.errors import one_line
from denoisebench.plugins import Limits
from denoisebench.sampling.harness import run_sampler
from denoisebench.sampling.isolation import IsolatedSampler, load, sampler_policy
from denoisebench.sampling.protocol import Budget, sampler_name
from denoisebench.sampling.synthetic import check_frame

BUDGETS = (4, 16, 64)
SEEDS = (0, 1, 2)
MAX_ERROR_RATIO = 0.25
BIAS_SLACK = 0.005
EPSILON = 0.01


@dataclass
class BudgetOutcome:
    spp: float
    rel_mse: float
    bias: float
    bias_se: float
    spent: float  # samples rendered / samples allowed (mean over seeds)
    pixels_without_samples: int  # the largest over seeds
    stopped: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    tracebacks: list[str] = field(default_factory=list)  # where the sampler raised, once each


@dataclass
class CheckOutcome:
    sampler: str
    budgets: list[BudgetOutcome]
    passed: bool
    reasons: list[str]

    def summary(self) -> dict:
        return {
            "sampler": self.sampler,
            "passed": self.passed,
            "reasons": self.reasons,
            "budgets": [vars(b) for b in self.budgets],
        }


def _one_budget(make_sampler, spp: float, seeds, size: int) -> BudgetOutcome:
    rel, deviations, variances, spent, empty, stopped, errors, traces = [], [], [], [], [], [], [], []
    for seed in seeds:
        frame = check_frame(size, size, seed=seed)
        try:
            sampler = make_sampler()
        except Exception as failure:  # noqa: BLE001 - a sampler that cannot even start fails the check
            errors.append(one_line(failure))
            continue
        try:
            result = run_sampler(sampler, frame, Budget(spp=spp))
        finally:
            _close(sampler)
        if result.error:
            errors.append(result.error)
        if result.traceback and result.traceback not in traces:
            traces.append(result.traceback)
        image = np.asarray(result.buffers["color"], dtype=np.float64)
        truth = frame.truth
        rel.append(float(np.mean((image - truth) ** 2 / (truth**2 + EPSILON))))
        deviations.append(float(np.mean((image - truth) / (truth + EPSILON))))
        with np.errstate(invalid="ignore"):
            var = np.nan_to_num(frame.expected_var(result.spp), posinf=0.0) / (truth + EPSILON) ** 2
        variances.append(float(var.sum()) / var.size**2)
        spent.append(result.samples / max(result.budget_samples or 1, 1))
        empty.append(result.pixels_without_samples)
        stopped.append(result.stopped)
    if not rel:
        return BudgetOutcome(spp, float("inf"), float("inf"), 0.0, 0.0, size * size, stopped, errors, traces)
    return BudgetOutcome(
        spp=spp,
        rel_mse=float(np.mean(rel)),
        bias=float(np.mean(deviations)),
        bias_se=float(np.sqrt(np.sum(variances))) / len(variances),
        spent=float(np.mean(spent)),
        pixels_without_samples=int(max(empty)),
        stopped=stopped,
        errors=errors,
        tracebacks=traces,
    )


def _close(sampler) -> None:
    """Stop an isolated sampler's worker (in-process samplers are left alone)."""
    if isinstance(sampler, IsolatedSampler):
        sampler.close()


def convergence_check(
    make_sampler, *, name: str = "sampler", budgets=BUDGETS, seeds=SEEDS, size: int = 32, progress=iter
):
    """Run the check (module docstring). ``make_sampler()`` returns a fresh sampler for each run.

    ``progress`` wraps the iteration over budgets (``tqdm`` on the command line).
    """
    outcomes = [_one_budget(make_sampler, spp, seeds, size) for spp in progress(budgets)]
    reasons = []
    first, last = outcomes[0], outcomes[-1]
    for outcome in outcomes:
        for error in sorted(set(outcome.errors)):
            reasons.append(f"{outcome.spp:g} spp: the sampler failed: {error}")
        if outcome.spent > 1.0 + 1e-9:
            reasons.append(f"{outcome.spp:g} spp: spent {outcome.spent:.3f} of the budget")
    if not last.rel_mse <= MAX_ERROR_RATIO * first.rel_mse:
        reasons.append(
            f"relMSE {first.rel_mse:.4g} at {first.spp:g} spp -> {last.rel_mse:.4g} at {last.spp:g} spp: "
            f"falls to {last.rel_mse / first.rel_mse if first.rel_mse else float('inf'):.2f} of it, "
            f"needs <= {MAX_ERROR_RATIO}"
        )
    bound = 4 * last.bias_se + BIAS_SLACK
    if not abs(last.bias) <= bound:
        reasons.append(f"relative bias {last.bias:+.4f} at {last.spp:g} spp, beyond {bound:.4f} (4 SE + {BIAS_SLACK})")
    if last.pixels_without_samples:
        reasons.append(f"{last.pixels_without_samples} pixels without a sample at {last.spp:g} spp")
    return CheckOutcome(sampler=name, budgets=outcomes, passed=not reasons, reasons=reasons)


def format_check(outcome: CheckOutcome) -> str:
    """The table ``check-plugin --sampler`` prints."""
    lines = [f"check-plugin --sampler {outcome.sampler} (synthetic frame of known truth, {len(SEEDS)} seeds)"]
    lines.append(f"{'spp':>6}  {'relMSE':>9}  {'rel. bias':>9}  {'± SE':>7}  {'spent':>6}  {'<1 spp':>6}  stopped")
    for b in outcome.budgets:
        lines.append(
            f"{b.spp:>6g}  {b.rel_mse:>9.4g}  {b.bias:>+9.4f}  {b.bias_se:>7.4f}  {b.spent:>6.3f}  "
            f"{b.pixels_without_samples:>6d}  {','.join(sorted(set(b.stopped)))}"
        )
    lines.extend(f"FAIL: {reason}" for reason in outcome.reasons)
    lines.append("converges: pass" if outcome.passed else "converges: FAIL")
    return "\n".join(lines)


def check_sampler(
    spec: str,
    options: dict,
    *,
    as_json: bool = False,
    isolation: str = "plugins",
    limits: Limits | None = None,
    verbose: bool = False,
) -> int:
    """``check-plugin --sampler SPEC``: load (a one-line error, exit 2, when it cannot), check, print; 0 pass, 1 fail.

    A plugin runs in a worker (:mod:`.isolation`, under ``limits``) unless ``isolation`` is ``"none"``
    (``"all"``: built-ins too). ``verbose``: the table is followed by where the sampler raised (the JSON
    always carries it, ``tracebacks`` of each budget).
    """
    policy = sampler_policy(isolation)

    def make_sampler():
        return load(spec, options, policy=policy, limits=limits)

    first = make_sampler()
    name = sampler_name(first, spec)
    _close(first)

    def progress(budgets):
        return tqdm(budgets, desc=f"check {name}", unit="budget", file=sys.stderr, leave=False)

    outcome = convergence_check(make_sampler, name=name, progress=progress)
    print(json.dumps({"spec": spec, **outcome.summary()}, indent=2) if as_json else format_check(outcome))
    if verbose and not as_json:
        traces = dict.fromkeys(trace for budget in outcome.budgets for trace in budget.tracebacks)
        for trace in traces:
            print(f"\ntraceback of the sampler:\n{trace.rstrip()}")
    return 0 if outcome.passed else 1
