"""Particle files no library writes from scratch, shared by the particle tests."""

# A water molecule in Tripos Mol2: MDAnalysis writes Mol2 only of a Mol2 it has read.
MOL2 = """@<TRIPOS>MOLECULE
water
3 2 1 0 0
SMALL
USER_CHARGES

@<TRIPOS>ATOM
      1 O1          0.0000    0.0000    0.1173 O.3     1  HOH1        0.0000
      2 H1          0.0000    0.7572   -0.4692 H       1  HOH1        0.0000
      3 H2          0.0000   -0.7572   -0.4692 H       1  HOH1        0.0000
@<TRIPOS>BOND
     1     1     2    1
     2     1     3    1
@<TRIPOS>SUBSTRUCTURE
     1 HOH1        1 RESIDUE    0 **** ROOT      0
"""
