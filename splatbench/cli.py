"""The `splatbench` command line."""

import click


@click.group()
def main() -> None:
    """splatbench: compare and validate 3D Gaussian Splatting rasterizers."""
