"""Training 3DGS through the Dr.Jit rasterizer (issue 5).

    from splatbench.train import TrainConfig, train
    result = train(TrainConfig(dataset="data/scenes/diffuse-128", iterations=2000))
    result.test_psnr, result.sh_degree, result.ply_path

Modules: `config` (TrainConfig, TOML, ``--set`` overrides), `initializers` (init by
name), `params` (parameter groups, Adam, position schedule), `losses` (L1 + D-SSIM),
`metrics` (PSNR, SSIM, optional LPIPS), `sh_schedule` (fixed and automatic SH degree),
`loop` (Trainer, train), `result` (TrainResult), `protocol` (quick / graphdeco-30k / graphdeco-7k),
`cli` (``splatbench train``).
See docs/training.md.
"""

from splatbench.train.config import TrainConfig, apply_overrides, load_config, save_config
from splatbench.train.loop import Trainer, train
from splatbench.train.result import EvalPoint, HistoryPoint, StepEvaluation, TrainResult

__all__ = ["TrainConfig", "TrainResult", "HistoryPoint", "EvalPoint", "StepEvaluation", "Trainer", "train", "apply_overrides",
           "load_config", "save_config"]
