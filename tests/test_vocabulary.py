"""A new term is one class: registered once, it is fitted, selected, reported and plotted."""

from functools import partial

import pandas as pd
import pytest

from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.physics.terms import VOCABULARY, Parameter, Term
from ptwin.reporting import figures
from tests.conftest import run, simulated_set


class RateStiffening(Term):
    """A toy: + c · base_speed · w (c [N s/m²]), a force growing with speed and depth."""

    name = "toy_rate_stiffening"
    PARAMS = {"c": Parameter("N s/m²", 0.0, minimum=0.0)}
    TELL_APART = "a toy needs no experiment"

    def force(self, samples, radius):
        return self.value("c") * samples.base_speed * samples.depth


def test_a_toy_term_is_fitted_selected_reported_and_plotted(tmp_path, coarse_cache, monkeypatch):
    monkeypatch.setitem(VOCABULARY, RateStiffening.name, RateStiffening)
    drawn = figures._drawn

    def titled(output_dir, builders, progress):
        """``_drawn``, each figure's first title written beside it: figures are drawn aside, and only files return."""

        def build(name, builder):
            figure = builder()
            (tmp_path / f"{name}.title").write_text(figure.axes[0].get_title())
            return figure

        return drawn(output_dir, {name: partial(build, name, b) for name, b in builders.items()}, progress)

    monkeypatch.setattr(figures, "_drawn", titled)
    truth = 20.0  # 6 nN at 80 µm/s and 4 µm: 20× the noise
    folder = simulated_set(tmp_path / "set", base_speeds=(0.5e-6, 8e-6, 80e-6), samples=500)
    recordings = load_recordings(folder)
    curves, k = recordings.curves, recordings.meta.spring_constant
    depth = (curves["z"] - curves["force"] / k).clip(lower=0.0)
    added = truth * curves["base_speed"] * depth
    # Force and base move together, so the recorded depth stays the simulated one.
    concealed = curves.assign(force=curves["force"] + added, z=curves["z"] + added / k)
    write_recordings(folder, recordings.meta, pd.DataFrame(concealed))

    outcome = run(
        folder,
        coarse_cache,
        tmp_path / "run",
        f"diagnosis.terms=[solid_viscosity,{RateStiffening.name}]",
        "optim.hybrid.regularisations=[1.0e-2]",
        "optim.hybrid.iterations=10",
        figures=True,
    )
    named = outcome.diagnosis["left_out"]
    assert [entry["term"] for entry in named] == [RateStiffening.name]
    assert named[0]["params"]["c"] == pytest.approx(truth, rel=0.1)
    assert f"Left out: `{RateStiffening.name}`" in (tmp_path / "run" / "report.md").read_text()
    assert outcome.figures["diagnosis_curves"] == tmp_path / "run" / "diagnosis_curves.png"
    assert outcome.figures["diagnosis_curves"].is_file()
    assert RateStiffening.name in (tmp_path / "diagnosis_curves.title").read_text()


def test_the_permeabilities_a_term_starts_from_follow_its_hooks_and_its_contact_caveat(monkeypatch):
    from types import SimpleNamespace

    import ptwin.fitting.physics_fit as physics_fit

    # Which terms can carry what the fluid force carries, read off their hooks: a rate or elastic force can.
    assert {name for name, term in VOCABULARY.items() if term.fluid_only()} == {
        "pore_pressure_relaxation",
        "strain_dependent_permeability",
        "contact_offset",
    }
    assert not RateStiffening.fluid_only()
    asked = []

    def make_model(terms, values, permeability=None):
        return SimpleNamespace(permeability=permeability, contact=None)

    def fit_physics(model, *rest, **options):
        asked.append(model.permeability)
        return SimpleNamespace(chi_square=1.0, physical=True)

    monkeypatch.setattr(physics_fit, "cheapest", lambda models, samples, index: list(models)[-1])
    monkeypatch.setattr(physics_fit, "fit_physics", fit_physics)
    fluid_off, base = (
        physics_fit.PLAUSIBLE_PERMEABILITY[1],
        SimpleNamespace(permeability=3e-16, params={}, reference_free=None),
    )
    for terms, starts in (
        (("pore_pressure_relaxation",), [None]),
        (("pore_pressure_relaxation", "strain_dependent_permeability"), [None]),
        # a viscosity (its CONTACT_CAVEAT): the base model's K too, and the base model's optimum itself
        (("pore_pressure_relaxation", "solid_viscosity"), [None, 3e-16, fluid_off, 3e-16]),
        (("cantilever_drag",), [None, fluid_off]),
    ):
        asked.clear()
        physics_fit.fit_with_starts(make_model, terms, None, None, base=base)
        assert asked == starts, terms


def test_each_permeability_start_is_fitted_whole_and_the_lower_chi_square_kept(monkeypatch):
    # Real agarose with 5 Pa·s added: settled with the reference's contact held, the default K looked better
    # (χ² 2424 against 2428); fitted whole, the fluid-off start reaches 2121 (γ 4.6) and must win.
    from types import SimpleNamespace

    import ptwin.fitting.physics_fit as physics_fit

    whole = {None: 2414.2, physics_fit.PLAUSIBLE_PERMEABILITY[1]: 2121.5}
    monkeypatch.setattr(physics_fit, "cheapest", lambda models, samples, index: list(models)[-1])
    monkeypatch.setattr(
        physics_fit,
        "fit_physics",
        lambda model, *rest, **options: SimpleNamespace(chi_square=whole[model], physical=True),
    )  # no base model given: the two K alone
    fit = physics_fit.fit_with_starts(lambda terms, values, permeability=None: permeability, ("solid_viscosity",), 0, 0)
    assert fit.chi_square == 2121.5


def test_a_physical_fit_is_kept_over_a_non_physical_one_of_lower_chi_square(monkeypatch):
    # Real PAAm with 5 Pa·s added: γ −5.9 at χ² 3844 from the default K, γ 5.8 at 3876 from the base model's K.
    # A term's parameters end at their physical range: the best fit within it is the one kept.
    from types import SimpleNamespace

    import ptwin.fitting.physics_fit as physics_fit

    base = SimpleNamespace(permeability=6.4e-16, model=None, reference_free=None)
    fits = iter([(3843.8, False), (3875.7, True), (19719.0, True), (4631.7, True)])  # in the order of the starts
    monkeypatch.setattr(physics_fit, "cheapest", lambda models, samples, index: list(models)[-1])
    monkeypatch.setattr(physics_fit, "started_at", lambda make_model, terms, start: "nested")

    def fit_physics(model, *rest, **options):
        chi_square, physical = next(fits)
        return SimpleNamespace(chi_square=chi_square, physical=physical)

    monkeypatch.setattr(physics_fit, "fit_physics", fit_physics)
    make_model = lambda terms, values, permeability=None: permeability  # noqa: E731
    assert physics_fit.fit_with_starts(make_model, ("solid_viscosity",), 0, 0, base=base).chi_square == 3875.7
    fits = iter([(3843.8, False), (3875.7, False), (19719.0, False), (4631.7, False)])  # none physical
    assert physics_fit.fit_with_starts(make_model, ("solid_viscosity",), 0, 0, base=base).chi_square == 3843.8


def test_a_model_started_at_a_neighbours_optimum_costs_what_the_neighbour_does_there(tmp_path, coarse_cache):
    # Each term at ``Term.absent_values`` does nothing: the model one term larger, started at a smaller one's
    # optimum (``started_at``), costs that model's χ², and its fit ends no higher (``fit_from``). Back the other way,
    # the smaller model started at the larger one's optimum costs the larger one's χ² with the term taken out
    # (``PhysicsFit.chi_square_without``). What ``diagnosis.name._nest`` relies on to make the candidates nest.
    from ptwin.fitting.physics_fit import fit_from, fit_physics, scaled_residual, started_at
    from ptwin.pipeline.prepare import prepare
    from tests.conftest import settings_for

    folder = simulated_set(tmp_path / "set", effects={"solid_relaxation": {"g": 0.3, "tau": 0.05}})
    p = prepare(settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}"), lambda _: None)

    def cost(model):
        vector, residual = scaled_residual(model, p.samples, p.split.train)
        return residual(vector.get()).square().sum().item()

    base = fit_physics(p.make_model(), p.samples, p.split.train)
    for term in VOCABULARY:
        assert cost(started_at(p.make_model, (term,), base)) == pytest.approx(base.chi_square, rel=1e-9), term
    larger = fit_from(p.make_model, ("solid_relaxation",), base, p.samples, p.split.train, 30, None)
    assert larger.chi_square < 0.5 * base.chi_square  # the relaxation concealed: the fit moved
    taken_out = larger.chi_square_without["solid_relaxation"]
    assert cost(started_at(p.make_model, (), larger)) == pytest.approx(taken_out, rel=1e-12)
    assert fit_from(p.make_model, (), larger, p.samples, p.split.train, 30, None).chi_square <= taken_out


def test_a_term_grown_onto_a_fit_finds_the_pair_from_where_it_does_nothing_and_from_where_it_acts(
    tmp_path, coarse_cache
):
    # A pore relaxation (M 2e5) beside a viscosity (γ 12): the pore alone runs off to M → ∞. Added to the viscosity's
    # optimum where it does nothing (``fit_from``), its gradient nearly nil, LM's first step had taken log M hundreds
    # of e-folds out, where it stayed (M → ∞); with every parameter fitted in log moved at most two decades a step
    # (``physics_solver``) it finds the pair, as it does added at the cheapest of its starting values (``grown``, the
    # diagnosis's forward step).
    from ptwin.fitting.physics_fit import fit_from, fit_physics, fit_with_starts
    from ptwin.pipeline.prepare import prepare
    from tests.conftest import settings_for

    effects = {"pore_pressure_relaxation": {"M": 2e5}, "solid_viscosity": {"gamma": 12.0}}
    folder = simulated_set(tmp_path / "set", effects=effects)
    p = prepare(settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}"), lambda _: None)
    base = fit_physics(p.make_model(), p.samples, p.split.train)
    viscosity = fit_with_starts(p.make_model, ("solid_viscosity",), p.samples, p.split.train, 60, base)
    pair = ("solid_viscosity", "pore_pressure_relaxation")
    for grown in (False, True):
        fit = fit_from(p.make_model, pair, viscosity, p.samples, p.split.train, 60, None, grown=grown)
        assert fit.chi_square < 0.3 * viscosity.chi_square and not fit.degenerate
        assert fit.params["pore_pressure_relaxation"]["M"] == pytest.approx(2e5, rel=0.05)
        assert fit.params["solid_viscosity"]["gamma"] == pytest.approx(12.0, rel=0.03)
