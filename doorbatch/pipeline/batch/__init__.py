"""``doorbatch run``: the whole pipeline over a dataset as a small DAG of steps, incremental and cron-safe.

    map:<site>                      OUT/<site>/map/                  ← the site's mapping logs
    localize:<site>/<log>/<method>  OUT/<site>/runs/<log>/<method>/  ← the log, the site's map
    evaluate:<site>                 OUT/<site>/report/               ← the site's runs, logs, truth
    report                          OUT/report/, OUT/metrics/, OUT/trajectories/  ← every site's report
"""
