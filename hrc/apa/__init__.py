"""APA: the Adaptive Preferences Algorithm (Wilcox, Nikolaidis & Shah, RSS 2012).

An STPP (`model`) is compiled into its dispatchably optimal form (`compile`, Fig. 5) by a convex QP
(`qp`) and dispatched online with recompilation on new preferences or deviations (`dispatch`, Fig. 8);
named preference sets tell worker types apart (`workers`, section VI). `io` reads and writes the STPP
JSON format, `generator` makes the paper's random structured STPPs (section V), `plan` reads an
`hrc` plan's STNU as an STP and values it (for the compiler and dispatcher). See docs/apa.md.
"""
