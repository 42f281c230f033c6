"""Fleet scale: a bag archive of many drivetrains on Dask, results in a database, wear trends.

One module per concept: :mod:`.archive` (which bags, whose drivetrain, when),
:mod:`.uncertainty` (standard deviations of a batch estimate), :mod:`.job` (what runs per
bag), :mod:`.database` (the results table), :mod:`.runner` (the Dask run),
:mod:`.trends` (gap against time, the date it crosses a limit), :mod:`.report` (the fleet
page and JSON summary) and :mod:`.synthetic` (a synthetic fleet with known wear).
"""
