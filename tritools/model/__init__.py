"""The triangulation problem as data: admissible regions (:mod:`.regions`), camera geometry (:mod:`.geometry`),
projection constraints (:mod:`.constraints`), the polynomial program (:mod:`.problem`) and the normalisation
that keeps it well scaled (:mod:`.normalize`).  Nothing here solves anything."""
