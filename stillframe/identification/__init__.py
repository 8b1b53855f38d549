"""Identification algorithms of thesis ch. 3 on numpy arrays: FRF, OKID, ERA, ERA/DC, modal
parameters, proportional damping, MKR, and the identified-model file. No middleware."""
