"""The field store's parts below its reader (:mod:`core.field_store`, the public names).

``schema`` (the names and numbers every store follows), ``writer`` (stores built slab by slab,
under a temporary name), ``attributes`` (the group attributes checked where a store is opened),
``digests`` (every array and attribute bound to a SHA-256), ``integrity`` (what ``rig verify``
checks). Callers import :mod:`core.field_store`, which re-exports what they need.
"""
