"""The physics: the compiled MDR kernel (``_kernel``), the checked ``Drive`` API (``model``),
the paper's analytic results (``analytic``), excitations (``excitation``), the physics
experiments behind the paper's figures (``experiments``) and the naive spring-row reference
(``naive``) that the tests and the work-precision study compare against."""
