"""CLI commands that run top-level modules or several packages: ``demo``, ``render``, ``sfm``.

Every other command lives in the ``cli.py`` of its package; `splatbench.cli` states the
layout and lists every command (`splatbench.cli.COMMANDS`).
"""
