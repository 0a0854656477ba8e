"""Campaigns: many runs of parametrised scenarios, judged and tabulated.

* :mod:`~twolevel.campaign.executor` — one ``concurrent.futures``-shaped executor: local
  processes by default, a Dask distributed cluster with ``tcp://HOST:PORT``;
* :mod:`~twolevel.campaign.case` — one case (a scenario, parameter values, a seed) run to its
  verdict in a worker, its concrete scenario written beside its run;
* :mod:`~twolevel.campaign.suite` — ``twolevel test``: every scenario and variant below paths;
* :mod:`~twolevel.campaign.sampling` — grids and random samples of a scenario's parameters;
* :mod:`~twolevel.campaign.falsify` — searches for the parameters that break a criterion;
* :mod:`~twolevel.campaign.results` — the results table (CSV, JSON, parquet) and its report.
"""
