"""The frame chain: what every frame of an exposure shares, and the compiled loops that draw a frame from it.

- :mod:`.plan`: :class:`~.plan.FramePlan` and :data:`~.plan.STAGES`, the one table of the temporal stages, from
  which the kernels' switches, the key rows and the GPU table's columns are derived by name;
- :mod:`.kernel`: the fused CPU kernel (numba), and the fixed maps' compiled loops;
- :mod:`.cuda_kernel` (host), :mod:`.cuda_device` (its kernels) and :mod:`.cuda_table` (the per-plan table's
  column indices, shared by both): the same chain on an NVIDIA GPU.

The NumPy specification the kernels are held to bit for bit is :mod:`cmosnoise.model.reference`.
"""
