"""``--model``, ``--up``, ``--model-views`` and ``--model-size``: trained models as workloads, for
`splatbench compare` and `splatbench bench raster` (one definition for both commands)."""

from __future__ import annotations

import click

from splatbench.bench.raster import MODEL_SIZE, MODEL_VIEWS, WorkloadSpec, parse_model
from splatbench.errors import InputError


def model_options(command):
    """Add the four options; the command receives ``models``, ``up``, ``model_views``, ``model_size``."""
    for option in reversed((
        click.option("--model", "models", multiple=True, metavar="FILE.ply|guitar|biker",
                     help="A trained 3DGS model as workloads: --model-views cameras around it, 20 degrees above "
                          "the horizontal (repeatable); guitar and biker are the bundled real models."),
        click.option("--up", default=None, metavar="AXIS|X,Y,Z",
                     help="The models' up axis (+y, -z, ... or X,Y,Z) [default: the one the PLY records, else -y]."),
        click.option("--model-views", "model_views", default=MODEL_VIEWS, show_default=True, type=int,
                     help="Cameras around each --model."),
        click.option("--model-size", "model_size", default=MODEL_SIZE, show_default=True, metavar="WxH",
                     help="Image size of the --model views."),
    )):
        command = option(command)
    return command


def model_specs(models, up, model_views: int, model_size: str) -> list[WorkloadSpec]:
    """The `WorkloadSpec`s of the ``--model`` options (one per model and view)."""
    if up is not None and not models:
        raise InputError("--up: applies to --model only")
    return [spec for m in models for spec in parse_model(m, up, model_views, model_size)]
