"""Scene variants sharded over every JAX device (one device: nothing changes).

Variants are independent until the final mean, so a 1-D device mesh over the variant axis lets
XLA run each device's variants locally and reduce once. The variant count is padded to a
multiple of the device count with copies of the last variant whose weight is 0.

The mesh spans `jax.devices()`, i.e. every device of every process after
`jax.distributed.initialize(...)`: each process holds the whole (cheap, seed-determined) batch
and `make_array_from_callback` hands every device its own slice, so several hosts split the
variants between them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

VARIANT_AXIS = "variants"


def shard_leading_axis(tree, pad_weight_index: int | None = None):
    """Pad the leading axis of every array in `tree` to a multiple of the device count and shard it.

    If `pad_weight_index` is given, `tree[pad_weight_index]` is the weight array whose padded
    entries are set to 0 (so padding never changes a mean).
    """
    devices = jax.devices()
    ndev = len(devices)
    if ndev == 1:
        return tree
    n = jax.tree.leaves(tree)[0].shape[0]
    pad = (-n) % ndev

    def pad_leaf(a):
        if pad == 0:
            return a
        return jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)], axis=0)

    tree = jax.tree.map(pad_leaf, tree)
    if pad and pad_weight_index is not None:
        tree = list(tree)
        tree[pad_weight_index] = tree[pad_weight_index].at[n:].set(0.0)
        tree = tuple(tree)
    mesh = Mesh(np.asarray(devices), (VARIANT_AXIS,))
    sharding = NamedSharding(mesh, PartitionSpec(VARIANT_AXIS))

    def place(a):
        host = np.asarray(a)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree.map(place, tree)
