"""Cross-validation of every solver on every mechanism (``baseparams validate``).

- :mod:`.jobs`: a job is (mechanism file text, solver name, options): plain data that a
  worker process or a Dask worker runs with nothing but the installed package and plugins;
- :mod:`.runners`: run jobs in-process, in a pool of local processes, or on a Dask cluster,
  each with a timeout; a job that dies or times out is reported, the others stay;
- :mod:`.model_checks`: checks of the model itself in ball arithmetic (energy balance,
  every transfer rule a null direction of W);
- :mod:`.checks`: the cross-solver comparisons, each the strongest its pair allows;
- :mod:`.validate`: puts them together into a report (text, Markdown, JSON);
- :mod:`.pytest_plugin`: ``baseparams_validate`` for third parties' test suites.
"""
