"""Run by tests/render/test_distributed.py in a subprocess with 4 host CPU devices (the XLA flag
must be set before jax is imported). Prints one JSON line: for the single-device ``render`` and
for ``render_sharded`` (rows, samples), under ``jax.jit``, the image and its derivative w.r.t.
the sphere's diffuse reflectance: forward mode gives the full tangent image (along the red
channel), reverse mode the gradient of the image mean.

Usage: python tests/render/_distributed_worker.py {jvp|grad}
"""

import os

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
os.environ["JAX_PLATFORMS"] = "cpu"

import json  # noqa: E402
import sys  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxgfx.render import load_scene, render, render_sharded  # noqa: E402

SCENE = {
    "camera": {
        "origin": [0, 1.0, 4.0],
        "target": [0, 0.6, 0],
        "fov": 40,
        "width": 16,
        "height": 14,
    },  # 14 rows: not divisible by 4 devices (padding rows)
    "shapes": [
        {"type": "sphere", "center": [0, 0.8, 0], "radius": 0.8, "material": "ball"},
        {
            "type": "rectangle",
            "center": [0, 0, 0],
            "normal": [0, 1, 0],
            "size": [6, 6],
            "material": "floor",
        },
    ],
    "materials": {
        "ball": {"type": "diffuse", "reflectance": [0.8, 0.5, 0.3]},
        "floor": {"type": "diffuse", "reflectance": 0.5},
    },
    "emitters": [
        {
            "type": "area",
            "shape": {
                "type": "rectangle",
                "center": [0, 3, 1],
                "normal": [0, -1, -0.3],
                "size": [1.2, 1.2],
            },
            "radiance": 8.0,
        },
        {"type": "constant", "radiance": 0.3},
    ],
}
SPP = 3  # not divisible by 4 devices (padded passes), not a square (no stratification)


def main(mode):
    scene = load_scene(SCENE)
    key = jax.random.key(7)
    r0 = jnp.array([0.8, 0.5, 0.3], jnp.float32)
    variants = {
        "single": lambda s: render(s, key, spp=SPP, integrator="direct"),
        "rows": lambda s: render_sharded(s, key, spp=SPP, integrator="direct", shard="rows"),
        "samples": lambda s: render_sharded(s, key, spp=SPP, integrator="direct", shard="samples"),
    }
    tangent = jnp.array([1.0, 0.0, 0.0], jnp.float32)
    out = {"n_devices": jax.device_count()}
    for name, f in variants.items():
        img_of = lambda r, f=f: f(scene.replace("materials.ball.reflectance", r))
        if mode == "jvp":
            img, dimg = jax.jit(lambda r, img_of=img_of: jax.jvp(img_of, (r,), (tangent,)))(r0)
        else:

            def loss(r, img_of=img_of):
                img = img_of(r)
                return img.mean(), img

            (_, img), dimg = jax.jit(jax.value_and_grad(loss, has_aux=True))(r0)
        out[name] = {"image": np.asarray(img).tolist(), "derivative": np.asarray(dimg).tolist()}
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
