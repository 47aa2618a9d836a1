"""Reading a solved certificate: minimiser extraction (:mod:`.extraction`, :mod:`.sparse_extraction`),
certification by verification of quadratic programs (:mod:`.verify`) and complexity counts (:mod:`.complexity`)."""
