"""Studies that regenerate ``results/``: the env's accuracy per scene (``accuracy``), the
work-precision study (``converge``), stability on stiff and extreme cases (``stability*``),
benchmarks (``bench*``) and the paper's figures (``figures``)."""
