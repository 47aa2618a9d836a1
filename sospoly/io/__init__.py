"""File formats of the conic standard form: SDPA sparse (:mod:`.sdpa`) and CBF (:mod:`.cbf`)."""
