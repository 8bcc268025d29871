"""ilic: identify, simulate and diagnose the dynamics of a drive axis.

Implements IDIM-LS and IDIM-ILIC (Gautier, Jubien, Janot, "Iterative Learning
Identification and Computed Torque Control of Robots").
"""

__version__ = "0.1.0"
