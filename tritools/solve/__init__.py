"""Solving triangulation problems: one point (:mod:`.triangulate`), many points (:mod:`.batch`), the
vectorised verification path (:mod:`.fastpath`) and the batched degree-2 SDP (:mod:`.sdp_batch`)."""
