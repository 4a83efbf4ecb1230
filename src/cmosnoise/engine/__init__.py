"""The noise engine: counter-based random numbers and the fused frame kernel.

- :mod:`.philox`: Philox4x32-10, a block of random words per (index, frame, sequence, try);
- :mod:`.fdmath`: log, exp, cos of a turn and log-gamma in plain IEEE float64;
- :mod:`.samplers`: normal (Box-Muller) and Poisson (inversion, PTRS) on those
  uniforms, vectorized with NumPy: the specification, and :class:`Stream`;
- :mod:`.frame`: the frame chain. Its plan and the one table of its temporal
  stages (:mod:`.frame.plan`); the same arithmetic fused into one numba loop
  over a frame or a region of it, parallel over rows (:mod:`.frame.kernel`);
  the same chain on an NVIDIA GPU, one thread per pixel, batches of frames or
  crops, the same bits (:mod:`.frame.cuda_kernel`, :mod:`.frame.cuda_device`).

Nothing here knows about configurations or sensors: arrays and numbers in,
arrays out.
"""
