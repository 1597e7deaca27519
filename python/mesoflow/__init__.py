"""mesoflow from Python: complex-fluid solvers on the GPU as graphs of compute nodes.

The engine::

    import numpy as np, mesoflow
    g = mesoflow.Graph("fcm", box=[32, 32, 32], tolerance=1e-3)   # by name or path
    prog = g.compile(outputs=["velocities"], positions=(1000, 3), forces=(1000, 3))
    out = prog.run(positions=x, forces=f)                           # numpy in, numpy out
    out["velocities"]                                               # (1000, 3) float32

A program keeps its GPU buffers, pipelines and state between calls; each `run` goes on
from the last step (fresh random draws), `reset()` starts over. Errors are
`mesoflow.GraphError` (the graph, its params, inputs or outputs: the messages of
`mesoflow validate`) and `mesoflow.RunError` (the GPU, or data a node refuses), both
RuntimeErrors.

libMobility's interface: `from mesoflow import libmobility` (SelfMobility, NBody, PSE,
FCM), see `mesoflow.libmobility`.
"""

from ._mesoflow import (  # noqa: F401
    Graph,
    GraphError,
    Program,
    RunError,
    adapters,
    device_summary,
    library,
)

__all__ = [
    "Graph",
    "GraphError",
    "Program",
    "RunError",
    "adapters",
    "device_summary",
    "library",
    "libmobility",
]


from . import libmobility  # noqa: E402,F401
