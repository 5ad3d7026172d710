"""jaxlie_geo's benchmarks: scripts run from the repository root as
``python -m benchmarks.<name>``, so that the checkout's jaxlie_geo is the one measured.

``common`` holds what they share (machine facts, labels, timing, options, raw files),
``report`` renders the results page from the raw files and ``plot`` draws its figures;
``benchmarks/README.md`` lists the scripts.
"""
