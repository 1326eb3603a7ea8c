"""The paper's Tables I–V from evaluated runs (``eigs tables``) and the figures (``eigs figures``): the paper's numbers
(:mod:`.paper`), one row per configured run averaged over scenes (:mod:`.collect`), rankings and distances to the
oracle (:mod:`.build`), CSV / Markdown / LaTeX (:mod:`.write`), matplotlib figures (:mod:`.figures`). No torch."""
