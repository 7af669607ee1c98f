"""Parameters of the results database and the evaluations (see ``docs/EVALUATION.md``)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class ResultsSettings(BaseModel):
    """``match_distance_m``: how far a plant's base may be from where it was seen before and
    still be the same plant (a quarter of the paper's 0.8 m spacing is far from any neighbour,
    and well above the few centimetres a base estimate moves as a seedling grows)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    match_distance_m: float = Field(default=0.15, gt=0.0)
    truth_match_distance_m: float = Field(default=0.15, gt=0.0)
