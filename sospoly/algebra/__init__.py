"""Polynomial algebra: sparse polynomials (:mod:`.polynomial`), monomial bases and Gram product tables
(:mod:`.basis`), polynomials affine in decision variables (:mod:`.linpoly`) and the one svec convention
(:mod:`.svec`)."""
