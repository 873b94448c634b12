import pytest

from ptwin.pgd.build import build_basis
from ptwin.pgd.config import Grid, PGDConfig, PlaneMesh, ThicknessMesh
from ptwin.pgd.enrichment import EnrichmentSettings


def small_config(**overrides) -> PGDConfig:
    """A coarse basis (seconds to build) with the structure of the real presets."""
    values = dict(
        plane=PlaneMesh(rings=6, edge_grading=2.0),
        thickness=ThicknessMesh(nodes=120, finest=1.0e-7),
        velocity=Grid(1.0e-8, 5.0e-4, 21),
        permeability=Grid(1.0e-19, 1.0e-13, 21),
        contact_radius=Grid(1.0e-7, 5.0e-5, 21),
        aspect_ratio=Grid(0.1, 1.0e5, 121),
        enrichment=EnrichmentSettings(max_modes=80, amplitude_tol=1e-5, output_tol=1e-7),
    )
    values.update(overrides)
    return PGDConfig(**values)


@pytest.fixture(scope="session")
def small_basis():
    return build_basis(small_config(), progress=lambda line: None)


@pytest.fixture(scope="session")
def basis_file(small_basis, tmp_path_factory):
    path = tmp_path_factory.mktemp("basis") / "small.pt"
    small_basis.save(path)
    return path
