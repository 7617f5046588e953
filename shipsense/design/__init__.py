"""Array design: Fisher information and Cramér–Rao bounds, observability and ambiguity, sensor placement.

Posterior CRLB: Tichavský, Muravchik & Nehorai, IEEE TSP 1998; placement: Joshi & Boyd, "Sensor selection via
convex optimization", IEEE TSP 2009.
"""
