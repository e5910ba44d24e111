"""Identification: a model from measured data.

* :mod:`flexarm.identification.time_domain`: closed-loop (or open-loop replay) logs →
  physical parameters, by simulating the logged experiment (output error);
* :mod:`flexarm.identification.frequency_domain`: periodic or sinusoidal experiments →
  frequency responses, their noise and distortion, transfer functions and physical fits
  (FRB Sec. II, multisines, ``tfest``).
"""
