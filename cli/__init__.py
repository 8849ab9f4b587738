"""MeshAdjust's command-line tools (not part of the Blender extension).

``batch`` is the batch converter, installed as the console script
``meshadjust-batch`` and run from a checkout as ``scripts/meshadjust_batch.py``.
"""
