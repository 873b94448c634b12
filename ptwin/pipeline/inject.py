"""What a recording set could have shown: a known term added to the user's own recordings, the rest real.

Method. The base model, K fitted on the set's training samples, gives the term's force ΔF on each curve's
recorded history: every rate force with the term minus without it, on the elastic force of the base model's
law (the hereditary terms act on it), at the base fit's contact corrections. Its rate forces start where its
elastic force does: the reference curve's own correction, a nuisance only the rate forces see
(``ptwin.physics.contact``), is not applied. Where the data do not pin it, it wanders within the reference's
onset, and a term added there would act where the recording has no force (bench-set p03: 62 nm before the
onset, so a viscosity pushed on samples before contact, and the diagnosis could fit only half of it). A force
added at the tip does not reach the recording whole: cantilever and sample share it. The balance k_c·(z − w) =
F(w, ẇ, …) with z as recorded is solved for the force δF the recording shows more: the model with the term
where that force leaves the sample (depth w' = w − δF/k_c, its rate ẇ' = ẇ − δḞ/k_c), less the model without
it at the recorded depth and rate, is δF. Newton's method from δF = 0 (``_Balance``): a sample's mismatch
moves with its own δF through the depth (the gain 1 + s/k_c, s = dF/dw the law's stiffness:
``ReferenceCurve.noise_gain``) and the rate (∂F/∂ẇ over k_c·Δt), and with the sample's before through the
rate, a lower bidiagonal system along each curve. Its first order, ΔF·k_c/(k_c + s) (0 before contact: all of
ΔF is deflection there), was off the balance on real PAAm by up to 2.9× the noise std (a drag of 1.5 nN; 0.6×
for a viscosity of 5 Pa·s, 1.4× for a power law), and three to five steps bring it within a thousandth of it
(a pore relaxation's, below: 0.005 after eight). On sets simulated with the term (the simulator solves the
balance) the force added comes 40× nearer the truth in rms than the first order (0.010 of the noise std for a
viscosity whose peak is 9× the noise, 0.070 for a drag; ``tests/test_inject.py``): Newton on the depth alone,
the rate left as recorded, stopped at 0.049 and 0.38, and with the rate moved but left out of the system it
diverged (the fluid's damping over k_c outlasting a sample's interval). δF is added to the recorded force; z,
time and the noise stay as recorded, and the depth follows (w = z − F/k_c).

Limits. A force that answers the rate with a lag (a pore relaxation) enters the steps by its response to a
lasting change of rate, more than its instant one: its steps converge slowly, and on a soft cantilever one was
3× the noise std off the balance after six (0.23 in rms against the simulator, 0.34 at first order). The
recording's own residual (its noise and what the model misses) stays at the recorded depth and does not move
with it. The term adds to whatever the recordings hold already, so each size is read against the diagnosis of
the recordings as they are. It is added on the base model's K, even where the data do not fix K. A term no
force added can stand for (``Term.NOT_INJECTED``: a contact offset, which moves where the recorded force
starts) is not added.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.linalg
import torch

from ptwin.data.recordings import write_recordings
from ptwin.diagnosis.diagnose import judged_test, parameter_interval
from ptwin.diagnosis.words import bounded, number, permeability_words
from ptwin.fitting.lm import FitError
from ptwin.fitting.physics_fit import PhysicsFit, fit_with_starts
from ptwin.physics.model import total
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY
from ptwin.pipeline.prepare import Prepared, prepare
from ptwin.pipeline.run import RunResult, candidate_settings, run
from ptwin.pipeline.settings import InjectRunSettings
from ptwin.threads import one_thread

BASE_PERMEABILITY = (
    "Beside a term not named, the base model's K: a rate force added can be carried by the base model's fluid force "
    "instead, and K falls for it."
)


FAILED = "failed or is not physical"  # a term's own fit where no strength is read from it


@dataclass(frozen=True)
class Own:
    """The term's strength the recordings fit as they are (``native_strength``): they hold some of any term's
    shape already (below the naming threshold, or a model error it projects onto), and a size added adds to it."""

    strength: str  # the term's strength parameter (its first)
    value: float | None  # the strength fitted; None where that fit failed or is not physical (read from ``absent``)
    absent: float = 0.0  # the strength at which the term does nothing (``Parameter.absent``)
    interval: list[float | None] | None = None  # its 95% profile interval (None: not profiled, or ``misses_data``)
    misses_data: bool = False  # the value is that of a model that leaves structure, which no interval bounds

    def beyond(self, found: float) -> float | None:
        """What a strength ``found`` adds to the recordings' own: the difference for a strength that acts from 0;
        for one whose term vanishes as it grows (a pore relaxation's M: its force is ∝ 1/M to first order), the
        strength whose 1/M is the difference of the two. None where ``found`` is no stronger than the own: the
        recordings as they are fit the term in another shape (bench-set p04: g 1.8 at tau 542 s, against 0.058
        at 0.11 s with g 0.064 added at 0.1 s), and the added size is not read over that."""
        own = self.absent if self.value is None else self.value
        if self.absent != math.inf:
            excess = found - own
            return excess if excess > 0 else None
        excess = 1.0 / found - 1.0 / own
        return 1.0 / excess if excess > 0 else None

    def share(self, beyond: float, added: float) -> float:
        """What a size found adds to the own (``beyond``'s answer) as a multiple of the size ``added``: in 1/M for a
        strength whose term vanishes as it grows."""
        return beyond / added if self.absent != math.inf else added / beyond

    def below(self) -> str:
        """Where a size found is not beyond the recordings' own (``beyond``), in words."""
        return f"the recordings as they are fit {self.fitted()}: the size found is not read over it"

    def words(self) -> str:
        """What a size found is read over, in words. A physical fit where the term does nothing is an own of that
        value, not a failed fit (a real PAAm place: "alpha fitted alone: 0 (95%: 0 to 0.0109)" had been said to
        have failed or not to be physical, the two compared by value)."""
        if self.value is None:
            return f"a size found is read whole: the recordings' own fit of {self.strength} {FAILED}"
        return f"a size found is read over the recordings' own {self.fitted()}"

    def fitted(self) -> str:
        """The strength the recordings fit, as the data fix it: a size found is read over the value, so the value is
        said, beside its 95% interval, or what the data say of it where they do not close it (bench-set p04 as
        recorded: "g 0.0651", a bare value the data may not fix)."""
        if self.value is None:
            return f"no {self.strength} (their fit {FAILED})"
        value = f"{self.strength} {self.value:.3g}"
        if self.interval is None and not self.misses_data:
            return value
        said = bounded(self.value, self.interval, ".3g", misses_data=self.misses_data)
        if self.misses_data or None not in self.interval:
            return f"{self.strength} {said}"
        if self.interval == [None, None]:
            return f"{value}, {said}"
        return f"{value}, though the data say only {self.strength} {said}"


@dataclass
class Trial:
    """One diagnosis of the recordings with the term added at ``size`` times its strength (0: as recorded)."""

    size: float
    added: float | None  # the strength added, in its unit (None: as recorded)
    peak: float  # the largest added force over the noise std on the judged samples (``judged_peak``)
    confidence: str  # the term's, if named; '' if not
    found: float | None  # the strength fitted, if named
    interval: list  # its 95% interval
    unexplained: bool
    candidate: bool  # whether the diagnosis fitted the term at all (see ``no_candidate``)
    alone: float | None = None  # the strength fitted with the term alone beside the base model, named or not
    others: tuple[tuple[str, str], ...] = ()  # the other terms the diagnosis named: (term, confidence)
    # the terms of ``others`` the diagnosis could not tell from the term (a group of ``diagnosis.json``'s "confounded")
    confounded: tuple[str, ...] = ()
    recorded: tuple[str, ...] = ()  # the terms of ``others`` the diagnosis of the recordings as they are names too
    why: tuple[str, ...] = ()  # where it was not named: the diagnosis's notes on the term (which rule left it out)
    permeability: float | None = None  # the base model's K in this diagnosis [m²]
    # of ``alone``, where its diagnosis profiled it (``Diagnosis.alone``): its 95% interval, or none where that fit
    # leaves structure (``alone_misses_data``); None: not profiled (its fit is not physical)
    alone_interval: list[float | None] | None = None
    alone_misses_data: bool = False

    def verdict(self, own: Own) -> str:
        """What the diagnosis said of the term, in words, and of any other term it named (a term added and
        read as another is the worst answer: "not named" alone would hide it, and where the diagnosis could not
        tell the two apart it says so); ``own``: the strength the recordings fit as they are. A term not named
        comes with the base model's K (``BASE_PERMEABILITY``; real agarose with 5 Pa·s added: from the limit
        of no fluid force to 1.2e-15 m²)."""
        strength = own.strength
        if not self.confidence:
            others = f"; the diagnosis named {self._listed()}{self._as_recorded()}" if self.others else ""
            if self.confounded:
                rivals, pair = self._listed(self.confounded), "the two" if len(self.confounded) == 1 else "them"
                if all(rival in self.recorded for rival in self.confounded):
                    # named as recorded too: not read in the term's place, yet no worse an account of the data
                    explain = "explains" if len(self.confounded) == 1 else "explain"
                    others += f"; {rivals} {explain} the data as well as the term added"
                else:
                    which = "" if len(self.confounded) == len(self.others) else f"; {rivals}"
                    others += f"{which} in its place"
                others += f": these recordings cannot tell {pair} apart"
            said = "unexplained" if self.unexplained else "not named"
            if not self.candidate:
                fitted = "no candidate in these recordings"
            else:
                fitted = None if self.alone is None else f"{strength} {self._alone_words()}"
            base = None if self.permeability is None else f"the base model's K {permeability_words(self.permeability)}"
            what = "; ".join(part for part in (fitted, base) if part)
            return f"{said} ({what}){others}" if what else f"{said}{others}"
        found = self.found_words()
        size = ""
        if self.added is not None:
            beyond = own.beyond(self.found)
            if beyond is None:
                size = f"; {own.below()}"
            else:  # beside the size added, whatever it is (real agarose B named a solid relaxation beside structure
                # no term explains at g 1.41e+03 for the 0.546 added)
                share = own.share(beyond, self.added)
                over = "read whole" if own.value is None else f"{number(beyond, '.3g')} over the recordings' own"
                size = f"; {over}, {share:.3g}× the size added"
        beside = f"; beside it {self._listed()}{self._as_recorded()}" if self.others else ""
        return f"named ({self.confidence}), {strength} {found}{size}{beside}"

    def found_words(self) -> str:
        """The strength found, with its 95% interval where one holds (``bounded``)."""
        return bounded(self.found, self.interval, ".3g", misses_data=self.unexplained)

    def _alone_words(self) -> str:
        """The strength fitted alone as the data fix it (``bounded``), where its diagnosis profiled it; else the
        value, said to be that of a fit that is not physical. Bench-set p03 with a solid relaxation of 32× the
        noise added (g 0.164) said "g 4.46 fitted alone", a flat direction's value: now "g fitted alone: not fixed
        by these data". A real PAAm place with a pore relaxation added said "M 1.16e+04 fitted alone", a fit whose
        elastic law falls with depth, rejected: a value no measurement unless said so (a negative gamma shows it,
        an M does not)."""
        if self.alone_interval is None and not self.alone_misses_data:
            return f"{self.alone:.3g} fitted alone, not physical"
        return "fitted alone: " + bounded(self.alone, self.alone_interval, ".3g", misses_data=self.alone_misses_data)

    def _listed(self, terms: tuple[str, ...] | None = None) -> str:
        """The other terms named (those of ``terms`` only, where given), each with its confidence."""
        listed = [(term, confidence) for term, confidence in self.others if terms is None or term in terms]
        return " + ".join(f"{term} ({confidence})" for term, confidence in listed)

    def _as_recorded(self) -> str:
        """Words for the other terms named that the recordings as they are name too: the added term was not read
        as those (a real creep names a solid relaxation and a power law as recorded, and with a viscosity added)."""
        if not self.recorded:
            return ""
        if len(self.recorded) == len(self.others):
            return ", as in the recordings as they are"
        return f"; {' + '.join(self.recorded)} as in the recordings as they are"


BALANCE_STEPS = 8  # Newton steps on the cantilever balance after the first, at most (the module docstring)


def added_force(
    prepared: Prepared, term: str, params: dict[str, float], base_fit: PhysicsFit | None = None
) -> dict[str, np.ndarray]:
    """δF [N] of every curve (the reference too: the term acts on all), per sample in file order, solved from the
    cantilever balance (the module docstring); ``base_fit``: the base model fitted to the set's training samples
    (fitted here when None)."""
    fit = base_fit or fit_with_starts(prepared.make_model, (), prepared.samples, prepared.split.train)
    base = copy.deepcopy(fit.model)
    if base.contact is not None:
        with torch.no_grad():
            base.contact.reference.zero_()  # every force from where the elastic force starts (the module docstring)
    with_term = prepared.make_model((term,), {term: params}, fit.permeability)
    with_term.contact = base.contact  # the base fit's contact corrections
    balance = _Balance(prepared, base, with_term)
    added = balance.newton(torch.zeros_like(balance.samples.force))[1]  # from nothing: the linear answer
    kept, worst = None, math.inf
    for _ in range(BALANCE_STEPS):
        try:
            mismatch, step = balance.newton(added)
        except (ValueError, RuntimeError):  # a depth off the model's reach (the fluid layer's grid)
            mismatch = step = torch.full_like(added, math.nan)
        size = mismatch.abs().max().item()
        if not size < worst:  # no nearer the balance (or off it): the step before is kept
            added = added if kept is None else kept
            break
        kept, worst = added, size
        added = added + step
        if step.abs().max().item() <= 1e-3 * prepared.noise.std:
            break
    measured, curve = added.cpu().numpy(), balance.samples.curve.cpu().numpy()
    return {curve_id: measured[curve == i] for i, curve_id in enumerate(balance.samples.curve_ids)}


class _Balance:
    """The cantilever balance with a term added, k_c·(z − w) = F(w, ẇ, …), z as recorded: how far a force added
    δF [N] leaves it from holding, and Newton's step towards it (the module docstring)."""

    def __init__(self, prepared: Prepared, base, with_term):
        self.prepared, self.base, self.with_term = prepared, base, with_term
        self.samples = Samples.from_curves(prepared.curves).to(prepared.samples.time.device)
        self.spring = prepared.recordings.meta.spring_constant
        time, start = self.samples.time, self.samples.start
        self.interval = torch.where(start, math.inf, time - time.roll(1))  # [s] since the sample before, in a curve
        self.recorded = self._force(self.base, self.samples)[0]
        self.nudge = 1e-3 * max(self.samples.velocity.abs().max().item(), 1e-9)  # [m/s] for ∂F/∂ẇ

    def _force(self, model, samples: Samples) -> tuple[torch.Tensor, torch.Tensor]:
        """The model's force [N] on ``samples``, on the base model's elastic law, and their depth [m]."""
        with torch.no_grad():
            depth = self.base.depth(samples)
            elastic = self.base.elastic(depth)
            return elastic + total(model.rate_forces(samples, elastic)), depth

    def moved(self, added: torch.Tensor) -> Samples:
        """The samples where a force ``added`` [N] leaves them: the depth w = z − F/k_c, its rate by the
        differences a sample's from the one before (backward Euler, as the step's solve)."""
        shift = added / self.spring
        rate = torch.where(self.samples.start, 0.0, (shift - shift.roll(1)) / self.interval)
        return replace(self.samples, depth=self.samples.depth - shift, velocity=self.samples.velocity - rate)

    def newton(self, added: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(How far from the balance ``added`` is, 0 where it holds; Newton's step from it) [N]. A sample's
        mismatch moves with its own δF through the depth (the gain 1 + s/k_c) and through the depth's rate (∂F/∂ẇ
        over k_c·Δt), and with the sample's before through the rate: a lower bidiagonal system, solved along each
        curve: with the rate in it, the steps converge where the fluid's damping over k_c outlasts a sample's
        interval."""
        samples = self.moved(added)
        force, depth = self._force(self.with_term, samples)
        mismatch = added - (force - self.recorded)
        faster = replace(samples, velocity=samples.velocity + self.nudge)
        lag = (self._force(self.with_term, faster)[0] - force) / self.nudge / (self.spring * self.interval)
        gain = torch.from_numpy(self.prepared.noise_gain(depth.cpu().numpy())).to(added)
        bands = torch.stack([gain + lag, -lag.roll(-1).where(~self.samples.start.roll(-1), 0.0)]).cpu().numpy()
        step = scipy.linalg.solve_banded((1, 0), bands, -mismatch.cpu().numpy())
        return mismatch, torch.from_numpy(step).to(added)


def write_injected(
    prepared: Prepared, term: str, params: dict[str, float], folder: Path, base_fit: PhysicsFit | None = None
) -> float:
    """The recordings with ``term`` at ``params`` added, written into ``folder``; the peak δF over the noise std
    (``judged_peak``)."""
    frame = prepared.recordings.curves.copy()
    forces = added_force(prepared, term, params, base_fit)
    for curve_id, force in forces.items():
        rows = (frame["curve"] == curve_id).to_numpy()
        frame.loc[rows, "force"] = frame.loc[rows, "force"].to_numpy() + force
    meta = prepared.recordings.meta
    added = ", ".join(f"{name} {value:.3g}" for name, value in params.items())
    note = f"ptwin.inject: {term} ({added}) added to {prepared.recordings.path}"
    write_recordings(folder, replace(meta, notes=f"{meta.notes}; {note}" if meta.notes else note), frame)
    return judged_peak(prepared, forces)


def judged_peak(prepared: Prepared, added: dict[str, np.ndarray]) -> float:
    """The largest of ``added`` (``added_force``) over the noise std on the samples the diagnosis judges: in
    contact and pinning a contact on the fitted curves, not the reference's approach, which is the elastic law
    (on a real creep, a viscosity's 64× the noise there is 53× in the creep)."""
    judged = (np.abs(added[c.curve][c.in_contact | c.pins_contact]) for c in prepared.fitted)
    return max(float(force.max(initial=0.0)) for force in judged) / prepared.noise.std


@one_thread()
def detection(settings: InjectRunSettings, output_dir: Path, progress: Callable[[str], None] = print) -> list[Trial]:
    """Diagnose the recordings as they are, then with the term added at each size; the report of the first
    gets a section on what these recordings could have shown. On one thread, its sizes' fits as each diagnosis
    (``ptwin.threads``)."""
    inject = settings.inject
    strength = VOCABULARY[inject.term].strength()
    progress(f"inject: the recordings as they are ({len(inject.sizes) + 1} diagnoses in all)")
    as_recorded, prepared, base_fit = _as_recorded(settings, output_dir, [inject.term])
    trials = [_trial(0.0, None, 0.0, as_recorded, inject.term, strength)]
    own = native_strength(prepared, inject.term, settings, base_fit, trials[0])
    progress(f"  as recorded: {trials[0].verdict(own)}; {own.words()}")
    for i, size in enumerate(sorted(inject.sizes), start=1):
        params = inject.scaled(size)
        trial = _added(settings, prepared, base_fit, as_recorded, inject.term, params, output_dir / f"size-{size:g}")
        trials.append(replace(trial, size=size))
        added = f"{strength} {params[strength]:.3g} added (peak {trial.peak:.1f}× the noise)"
        progress(f"  [{i}/{len(inject.sizes)}] {added}: {trial.verdict(own)}")
    section, full = detection_section(inject.term, trials, own, settings.diagnosis.terms), _full(as_recorded, settings)
    _append(output_dir, section + full)
    progress("\n".join(section[-1:] + full[1:]))
    return trials


@one_thread()
def detection_limits(
    settings: InjectRunSettings, output_dir: Path, progress: Callable[[str], None] = print
) -> dict[str, list[Trial]]:
    """What these recordings could have shown of every candidate term: each added at the sizes whose peak
    over the noise std is ``LADDER``'s, smallest first, until the diagnosis names it (``inject.term: all``).
    A term's size is its strength (first parameter) times a factor, its other parameters ``Term.TYPICAL``;
    the factor for a peak is read off a grid of the added force (cheap: no diagnosis). A term the recordings as
    they are name is not added: every size would be named, and the ladder would read the recordings, not the
    size (a real creep named solid_relaxation and power_law_rheology: both "named" at 8× the noise, for sizes
    a fifteenth of what it holds). The report of the recordings as they are gets a section with each term's
    smallest size named."""
    progress("inject: the recordings as they are, then every candidate term at growing sizes until named")
    as_recorded, prepared, base_fit = _as_recorded(settings, output_dir, settings.diagnosis.terms)
    terms = candidate_settings(prepared, settings)[0].terms
    found, native, already = {}, {}, set()
    for i, term in enumerate(terms, start=1):
        found[term] = []
        if VOCABULARY[term].NOT_INJECTED:
            progress(f"  [{i}/{len(terms)}] {term}: not added: {VOCABULARY[term].NOT_INJECTED}")
            continue
        strength = VOCABULARY[term].strength()
        recorded = _trial(0.0, None, 0.0, as_recorded, term, strength)
        native[term] = native_strength(prepared, term, settings, base_fit, recorded)
        if recorded.confidence:  # every size would be named: the ladder would read the recordings, not the size
            already.add(term)
            held = f"{strength} {recorded.found_words()}"
            progress(f"  [{i}/{len(terms)}] {term}: {ALREADY} ({recorded.confidence}), {held}; not added")
            continue
        ladder = _ladder(prepared, term, base_fit)
        for peak, params in ladder:
            folder = output_dir / f"{term}-peak-{peak:g}"
            trial = _added(settings, prepared, base_fit, as_recorded, term, params, folder)
            found[term].append(trial)
            progress(
                f"  [{i}/{len(terms)}] {term}: {strength} {params[strength]:.3g} (peak {trial.peak:.1f}× the noise): "
                f"{trial.verdict(native[term])}"
            )
            if trial.confidence:
                break
        else:  # never named: a ladder cut short says where it stops, as the table does (``limits_section``)
            if len(ladder) < len(LADDER):
                stop = "no larger size tried" if ladder else "not added"
                progress(f"  [{i}/{len(terms)}] {term}: {_reach(LADDER[len(ladder)], strength)}: {stop}")
    _append(output_dir, limits_section(found, native, already) + _full(as_recorded, settings))
    return found


def _as_recorded(
    settings: InjectRunSettings, output_dir: Path, terms: list[str]
) -> tuple[RunResult, Prepared, PhysicsFit]:
    """The recordings as they are: diagnosed as train.py would (its output in ``output_dir/as-recorded``), each of
    ``terms`` fitted alone profiled, prepared, and the base model fitted to their training samples (what every term
    is added on)."""
    as_recorded = run(_profiling(settings, terms), output_dir / "as-recorded", _quiet)
    prepared = prepare(settings, _quiet)
    return as_recorded, prepared, fit_with_starts(prepared.make_model, (), prepared.samples, prepared.split.train)


def _added(
    settings: InjectRunSettings,
    prepared: Prepared,
    base_fit: PhysicsFit,
    as_recorded: RunResult,
    term: str,
    params: dict[str, float],
    folder: Path,
) -> Trial:
    """``term`` at ``params`` added to the recordings (written in ``folder/recordings``) and diagnosed as train.py
    would (in ``folder/run``): its ``Trial``, its size the strength added."""
    strength = VOCABULARY[term].strength()
    peak = write_injected(prepared, term, params, folder / "recordings", base_fit)
    data = replace(settings.data, path=str(folder / "recordings"))
    outcome = run(replace(_profiling(settings, [term]), data=data), folder / "run", _quiet)
    return _trial(params[strength], params[strength], peak, outcome, term, strength, as_recorded)


def _profiling(settings: InjectRunSettings, terms: list[str]) -> InjectRunSettings:
    """``settings`` whose diagnosis profiles the strength of each of ``terms`` fitted alone (``Diagnosis.alone``):
    a size not named is said with its interval, not as a bare value."""
    return replace(settings, diagnosis=replace(settings.diagnosis, profiled=list(terms)))


def _append(output_dir: Path, section: list[str]) -> None:
    """``section`` at the end of the report of the recordings as they are."""
    with (output_dir / "as-recorded" / "report.md").open("a") as report:
        report.write("\n" + "\n".join(section) + "\n")


LADDER = (8.0, 16.0, 32.0, 64.0)  # peaks of the added force over the noise std, tried smallest first
ALREADY = "named in the recordings as they are"  # a term not added: every size would be named (``detection_limits``)
_FACTORS = np.geomspace(1e-3, 1e3, 13)  # of a term's typical strength: the grid its peaks are read off (log-log)


def _ladder(prepared: Prepared, term: str, base_fit: PhysicsFit) -> list[tuple[float, dict[str, float]]]:
    """(peak over the noise std, the term's parameters) for each of ``LADDER``'s peaks the term reaches within
    its physical range: its strength bracketed where the grid of ``_FACTORS`` first crosses the peak, walking from
    weak to strong (a smaller M is a stronger pore relaxation), then found in the bracket (``_crossing``)."""
    cls = VOCABULARY[term]
    strength = cls.strength()
    parameter = cls.PARAMS[strength]

    def peak(value: float) -> float:
        return judged_peak(prepared, added_force(prepared, term, {**cls.TYPICAL, strength: value}, base_fit))

    values = [cls.TYPICAL[strength] * f for f in _FACTORS]
    values = [v for v in values if parameter.maximum is None or v < parameter.maximum]
    peaks = [peak(value) for value in values]
    if peaks[0] > peaks[-1]:
        values, peaks = values[::-1], peaks[::-1]
    ladder = []
    for target in LADDER:
        above = next((j for j, p in enumerate(peaks) if p >= target), None)
        if above is None:
            break
        bracket = values[above - 1], peaks[above - 1], values[above], peaks[above]
        value = values[0] if above == 0 else _crossing(peak, target, *bracket)
        ladder.append((target, {**cls.TYPICAL, strength: value}))
    return ladder


PEAK_TOLERANCE = 0.02  # relative: how near a ladder's size peaks to the peak asked for


def _crossing(
    peak: Callable[[float], float], target: float, weaker: float, low: float, stronger: float, high: float
) -> float:
    """The strength between ``weaker`` (peak ``low`` < ``target``) and ``stronger`` (peak ``high`` ≥ it) whose
    ``peak`` is within ``PEAK_TOLERANCE`` of ``target``: interpolated log-log (exact where the peak is a power of
    the strength, as for most terms), the bracket narrowed to the side the peak falls on until it is (the stronger
    end after 50 steps). Interpolated once, a strain-dependent permeability's m on real agarose, whose force grows
    steeply near its largest, had peaked at 5.6 and 8.5× the noise for 8 and 16."""
    for _ in range(50):
        if low > 0:
            share = math.log(target / low) / math.log(high / low)
            middle = math.exp(math.log(weaker) + share * math.log(stronger / weaker))
        else:  # a term that does nothing at the weaker end: no logarithm there
            middle = math.sqrt(weaker * stronger)
        reached = peak(middle)
        if abs(reached / target - 1.0) <= PEAK_TOLERANCE:
            return middle
        if reached < target:
            weaker, low = middle, reached
        else:
            stronger, high = middle, reached
    return stronger


def limits_section(found: dict[str, list[Trial]], native: dict[str, Own], already: set[str]) -> list[str]:
    """report.md's section of ``detection_limits``: each term's smallest size named, or the largest tried (a
    size found is read against the term's ``native`` strength, as ``detection`` reads it); ``already``: the terms
    the recordings as they are name, not added."""
    lines = [
        "## What these recordings could have shown",
        "",
        "Each candidate term added to these recordings through the cantilever balance, everything "
        "else as recorded, at sizes whose peak is "
        + ", ".join(f"{p:g}" for p in LADDER)
        + "× the noise std, smallest first, until named (`python -m ptwin.inject inject.term=all`; method and "
        "limits in `ptwin/pipeline/inject.py`). " + BASE_PERMEABILITY,
        "",
        "| term | smallest size named | peak / noise std | verdict there | largest tried and not named |",
        "|---|---|---|---|---|",
    ]
    for term, trials in found.items():
        strength = VOCABULARY[term].strength()
        if term in already:
            lines.append(f"| `{term}` | {ALREADY} ({native[term].fitted()}): not added | – | – | – |")
            continue
        if VOCABULARY[term].NOT_INJECTED:
            lines.append(f"| `{term}` | not added: {VOCABULARY[term].NOT_INJECTED} | – | – | – |")
            continue
        if not trials:
            lines.append(f"| `{term}` | {_reach(LADDER[0], strength)}: not added | – | – | – |")
            continue
        parameter = VOCABULARY[term].PARAMS[strength]
        named = next((t for t in trials if t.confidence), None)
        missed = [t for t in trials if not t.confidence]
        last = "–"
        if missed:
            verdict = missed[-1].verdict(native[term])
            last = f"{strength} {parameter.quantity(missed[-1].added)} ({missed[-1].peak:.0f}×: {verdict})"
        if named is None:
            # a ladder cut short: no size tried reaches its next peak (a pore relaxation on the shared p03: 16× the
            # noise at M 89.9 Pa, below 32× at every M tried down to 30 Pa)
            short = f"; {_reach(LADDER[len(trials)], strength)}" if len(trials) < len(LADDER) else ""
            tried = f"not named up to a peak of {trials[-1].peak:.0f}× the noise{short}"
            lines.append(f"| `{term}` | {tried} | – | – | {last} |")
        else:
            lines.append(
                f"| `{term}` | {strength} {parameter.quantity(named.added)} | {named.peak:.1f} | "
                f"{named.verdict(native[term])} | {last} |"
            )
    return lines


def _reach(peak: float, strength: str) -> str:
    """Words for a term whose sizes tried (``_ladder``: its ``strength`` over ``_FACTORS`` of a typical one) never
    reach ``peak`` (over the noise std)."""
    tried = f"{strength} {_FACTORS[0]:g} to {_FACTORS[-1]:g} times a typical one (as physical)"
    return f"its peak stays below {peak:g}× the noise for {tried}"


def _full(as_recorded: RunResult, settings: InjectRunSettings) -> list[str]:
    """A line where the recordings as they are name ``diagnosis.max_terms`` terms already: a term added can be named
    beside them all only in a larger subset, which the diagnosis does not fit (a real creep names two), and within
    the cap only in place of one of them (a real brain creep with 5 Pa·s added: the viscosity and the pore term,
    where the recordings named a power law and the pore term)."""
    named = [entry["term"] for entry in as_recorded.diagnosis["left_out"]]
    cap = settings.diagnosis.max_terms
    if not named or len(named) < cap:
        return []
    beside = {1: "it", 2: "both"}.get(len(named), f"all {len(named)}")
    instead = "in its place" if len(named) == 1 else "in place of one of them"
    return [
        "",
        f"The recordings as they are name {' + '.join(named)}, diagnosis.max_terms ({cap}) already: a term added is "
        f"named beside {beside} only with diagnosis.max_terms={len(named) + 1}; within {cap}, only {instead}.",
    ]


def _quiet(_: str) -> None:
    """Progress of the runs inside an injection, not shown."""


def _trial(
    size: float,
    added: float | None,
    peak: float,
    outcome: RunResult,
    term: str,
    strength: str,
    as_recorded: RunResult | None = None,
) -> Trial:
    """The ``Trial`` of one diagnosis (``outcome``); ``as_recorded``: that of the recordings as they are, where
    ``outcome`` is one with the term added."""
    diagnosis, candidate = outcome.diagnosis, term in outcome.candidates
    unexplained, permeability = diagnosis["unexplained"], outcome.base_permeability
    named = [e for e in diagnosis["left_out"] if e["term"] != term]
    others = tuple((e["term"], e["confidence"]) for e in named)
    before = set() if as_recorded is None else {e["term"] for e in as_recorded.diagnosis["left_out"]}
    recorded = tuple(e["term"] for e in named if e["term"] in before)
    entry = next((e for e in diagnosis["left_out"] if e["term"] == term), None)
    if entry is None:
        alone = (outcome.candidates.get(term) or {}).get(strength)
        alone_interval = outcome.alone.get(term)  # absent where not profiled, None where its fit leaves structure
        alone_misses_data = term in outcome.alone and alone_interval is None
        why = tuple(note for note in diagnosis["notes"] if term in note)
        rivals = {other for group in diagnosis["confounded"] if term in group["terms"] for other in group["terms"]}
        confounded = tuple(e["term"] for e in named if e["term"] in rivals)
        return Trial(
            size,
            added,
            peak,
            "",
            None,
            [None, None],
            unexplained,
            candidate,
            alone,
            others,
            confounded=confounded,
            recorded=recorded,
            why=why,
            permeability=permeability,
            alone_interval=alone_interval,
            alone_misses_data=alone_misses_data,
        )
    value, interval = entry["params"][strength], entry["param_interval"][strength]
    return Trial(
        size,
        added,
        peak,
        entry["confidence"],
        value,
        interval,
        unexplained,
        candidate,
        others=others,
        recorded=recorded,
    )


def no_candidate(term: str, trials: list[Trial], listed: list[str]) -> str | None:
    """Why no size could have been named where the diagnosis fitted ``term`` in none of the recordings it was
    added to (a drag where free per-curve offsets remove it with each curve's level); None otherwise.
    ``listed``: the diagnosis's terms as configured (``diagnosis.terms``)."""
    if any(t.candidate for t in trials[1:]):
        return None
    if term not in listed:
        reason = "it is not among diagnosis.terms"
    else:
        reason = VOCABULARY[term].WITH_ESTIMATED_CONTACT or "diagnosis.max_terms is 0: no term is fitted"
    return f"{term} was no candidate in these recordings ({reason}): no size of it can be named in them"


def native_strength(
    prepared: Prepared, term: str, settings: InjectRunSettings, base_fit: PhysicsFit, as_recorded: Trial
) -> Own:
    """The term's strength the recordings fit as they are, named or not: what a size found is read against.
    Where their diagnosis (``as_recorded``) names it, its value there, beside the other terms named with it (a
    size added is then found in that model: on a real creep named with a power law, g 0.148, where alone it fits
    0.251); else, where it fitted the term, the term fitted alone there with its profile (``Trial.alone``), under
    the noise model that diagnosis read everything under: fitted again here, under the one ``prepare`` reads
    before a diagnosis caps it, a real PAAm place said "gamma fitted alone: 0.246 (95%: 0 to 0.85)" and "read over
    the recordings' own gamma 0.246 (95%: 0 to 1.11)" in one line. Where it did not (no candidate there: a drag
    whose removed per-curve levels take it), fitted alone here, from the starts the diagnosis gives it
    (``base_fit``: the base model fitted to the training samples), its interval under the structure test's noise as
    the diagnosis reads one (``settings.diagnosis``)."""
    strength = VOCABULARY[term].strength()
    parameter = VOCABULARY[term].PARAMS[strength]
    absent = 0.0 if parameter.absent is None else parameter.absent  # a strength no one value removes: read from 0
    if as_recorded.confidence:
        return Own(strength, as_recorded.found, absent, list(as_recorded.interval), as_recorded.unexplained)
    if as_recorded.candidate:  # profiled where that fit is physical (``_profiling``), else failed or not physical
        if as_recorded.alone_interval is None and not as_recorded.alone_misses_data:
            return Own(strength, None, absent)
        interval = None if as_recorded.alone_misses_data else list(as_recorded.alone_interval)
        return Own(strength, as_recorded.alone, absent, interval, misses_data=as_recorded.alone_misses_data)
    samples, train = prepared.samples, prepared.split.train
    try:
        fit = fit_with_starts(
            prepared.make_model, (term,), samples, train, settings.optim.physics_fit.iterations, base_fit
        )
    except FitError:
        return Own(strength, None, absent)
    if not fit.physical:
        return Own(strength, None, absent)
    # the structure test on the term fitted alone is the diagnosis's (``Trial.alone_misses_data``)
    test = judged_test(samples, prepared.split, prepared.make_model.reference, prepared.noise, settings.diagnosis)
    interval = parameter_interval(fit, term, strength, samples, train, test)
    return Own(strength, fit.params[term][strength], absent, interval, as_recorded.alone_misses_data)


def detection_section(term: str, trials: list[Trial], own: Own, listed: list[str]) -> list[str]:
    """report.md's section: each size added, the verdict (the size found over the recordings' ``own``
    strength), what the diagnosis said of the term where it was added and not named (the rule that
    left it out, in its own words), and the smallest size named (``listed``: ``diagnosis.terms``, for why none
    could be)."""
    strength = own.strength
    lines = [
        "## What these recordings could have shown",
        "",
        f"`{term}` added to these recordings through the cantilever balance, everything else as "
        "recorded (`python -m ptwin.inject`; method and limits in `ptwin/pipeline/inject.py`). " + BASE_PERMEABILITY,
        "",
        f"| {strength} added | peak added force / noise std | verdict |",
        "|---|---|---|",
    ]
    for trial in trials:
        added = "as recorded" if trial.added is None else f"{trial.added:.3g}"
        lines.append(f"| {added} | {trial.peak:.1f} | {trial.verdict(own)} |")
    unnamed = [t for t in trials[1:] if t.why]
    if unnamed:
        lines += ["", f"Where `{term}` was added and not named, what the diagnosis said of it:"]
        lines += [f"- {strength} {t.added:.3g} added: {note}" for t in unnamed for note in t.why]
    named = [t for t in trials[1:] if t.confidence]
    if named:
        smallest = f"The smallest {strength} named: {named[0].added:.3g} (peak {named[0].peak:.1f}× the noise std)."
    else:
        # Not "the recordings do not show it": a term fitted alone near its size can still be left unnamed.
        reason = no_candidate(term, trials, listed)
        tried = f"No size tried was named ({strength} up to {trials[-1].added:.3g})"
        smallest = f"{tried}: {reason}." if reason else f"{tried}."
    return [*lines, "", smallest]
