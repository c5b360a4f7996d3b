"""The fast path: ahead-of-time compiled steps and rollouts (`compiled`), a model prepared for
compilation (`prepared`, `stepper`, `knn_index`), two fixes to AOTInductor's wrapper
(`codegen_fixes`), portable `.pt2` exports (`export`) and the rule that picks the compiled or
the eager path (`payoff`). Training and run directories never
import it; evaluation only when a compiled prediction is asked for (``--compiled``)."""
