from fieldapp.recon.settings import GridPrior, ReconstructionSettings
from fieldapp.settings import Settings, validate_leniently


def test_paper_defaults_are_mounted_in_the_app_settings() -> None:
    settings = Settings().reconstruction
    assert settings.crop.radius_m == 2.25
    assert settings.filters.exg_threshold == "otsu"
    assert (settings.filters.sor_neighbors, settings.filters.sor_std_ratio) == (35, 1.5)
    assert settings.filters.ror_radius_m == 0.008
    assert settings.registration.enabled and settings.plants.grid is None


def test_a_bad_reconstruction_field_falls_back_to_its_default() -> None:
    values = {"reconstruction": {"crop": {"radius_m": -1}, "filters": {"exg_threshold": 0.1}}}
    settings = validate_leniently(values, "test")
    assert settings.reconstruction.crop.radius_m == 2.25
    assert settings.reconstruction.filters.exg_threshold == 0.1


def test_grid_prior_round_trips() -> None:
    grid = GridPrior(rows=4, columns=4, row_spacing_m=0.8, column_spacing_m=0.8)
    settings = ReconstructionSettings.model_validate({"plants": {"grid": grid.model_dump()}})
    assert settings.plants.grid == grid
