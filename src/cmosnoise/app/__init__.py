"""The commands and what they run: layer 7, the top.

- :mod:`.cli` (and :mod:`.entry`, the console script): each command parses
  its options and calls a job;
- jobs: :mod:`.run` (``simulate``, ``process``), :mod:`.characterizing`
  (``characterize``), :mod:`.fitting` (``fit``, ``measure``), :mod:`.sweep`
  (parameter studies on Dask), :mod:`.explore` (the web page's server) with
  :mod:`.workbench` (its work, without HTTP);
- outputs: :mod:`.report`, :mod:`.fit_report`, :mod:`.figures` (the paper's
  figures), :mod:`.plots` (matplotlib through ``Figure``, no global backend);
- :mod:`.logs`: other libraries' loggers quieted while a command runs.

A new command is a function in :mod:`.cli` that calls a job here.
"""
