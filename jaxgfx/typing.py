"""Shape-annotated array aliases (jaxtyping) used across jaxgfx's public signatures."""

from jaxtyping import Array, ArrayLike, Bool, Float, Int, Shaped, UInt

Image = Float[Array, "*batch H W C"]
ImageLike = Float[ArrayLike, "*batch H W C"]
Gray = Float[Array, "*batch H W"]
AnyImage = Float[Array, "..."]  # (..., H, W) or (..., H, W, C)
Vec3 = Float[Array, "*batch 3"]
RGB = Float[Array, "*batch 3"]
Mat33 = Float[Array, "3 3"]
Scalar = Float[Array, ""]
Mask = Bool[Array, "*batch H W"]

__all__ = [
    "Array",
    "ArrayLike",
    "Bool",
    "Float",
    "Int",
    "Shaped",
    "UInt",
    "Image",
    "ImageLike",
    "Gray",
    "AnyImage",
    "Vec3",
    "RGB",
    "Mat33",
    "Scalar",
    "Mask",
]
