"""Campaigns: many runs of library scenarios with varied parameters, on a Dask cluster.

A campaign file (docs/campaigns.md) names base scenarios, the variations (distributions or
lists), a sample size or a grid, and extra expectations. Run N of a campaign is built from the
file and N alone (:func:`lowerbase.campaign.plan.plan_run`): its values are drawn from
``numpy.random.SeedSequence([seed, N])``, so any run can be replayed on its own.

Modules: ``spec`` (the validated file), ``plan`` (run N's scenario), ``execute`` (one run, on a
worker: the same in-process runners as ``lowerbase scenario run``), ``engine`` (Dask: a
LocalCluster or a scheduler's address), ``table`` (CSV), ``report`` (index.html and plots).
It runs lowerbase.scenarios' runners; only the robot and the CLI are above it.
"""
