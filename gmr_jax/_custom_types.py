from typing import Union

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

Scalar = Float[Array, ""]
ScalarLike = Union[float, Float[ArrayLike, ""]]
IntScalar = Int[Array, ""]

__all__ = ["Array", "ArrayLike", "Bool", "Float", "Int", "Scalar", "ScalarLike", "IntScalar", "np"]
