"""*What* certificate is sought, as pure data: SOS programs (:mod:`.program`), the Positivstellensatz
program of a polynomial optimisation problem (:mod:`.psatz`) and sparsity (:mod:`.sparsity`:
correlative cliques, Newton-polytope bases, term sparsity).  Nothing here imports a solver."""
