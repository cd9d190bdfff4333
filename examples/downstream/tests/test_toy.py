"""toy_splat's own tests. The conformance and regression items come from splatbench's pytest plugin
(see .github/workflows/splatbench.yml); this file checks one of the project's own scenes with the
plugin's ``splatbench_scene`` fixture."""

import numpy as np

from splatbench import Camera


def test_a_scene_of_ours_matches_the_oracle(splatbench_scene):
    rng = np.random.default_rng(0)
    n = 12
    camera = Camera.look_at(eye=[0.0, -0.5, -3.0], target=[0.0, 0.0, 0.0], up=[0.0, -1.0, 0.0], width=24, height=20,
                            fov_x_deg=50.0)
    splatbench_scene(rng.uniform(-0.4, 0.4, (n, 3)), np.log(rng.uniform(0.05, 0.15, (n, 3))), rng.normal(size=(n, 4)),
                     rng.normal(-0.5, 0.5, n), np.concatenate([rng.normal(0, 0.5, (n, 1, 3)),
                                                               rng.normal(0, 0.1, (n, 3, 3))], 1),
                     camera, backend="toy_splat:render")
