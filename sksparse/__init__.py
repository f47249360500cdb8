"""``sksparse``: the import name of scikit-sparse, as a face for the published lubrication drivers (top floor).

The published ``Lubrication/Lubrication_Examples/*/main_*.py`` drivers start with
``from sksparse.cholmod import cholesky`` and never call it (their solves go through ``Lub_Solver``); scikit-sparse
has no wheel for this package's Pythons (it builds against the SuiteSparse library).  This face makes that import
work after the package's own install: :mod:`sksparse.cholmod` offers ``cholesky`` of a sparse symmetric positive
definite matrix through the package's sparse LDL^T (:mod:`lubrication.sparse_factor`; SciPy's SuperLU where its
extension is not built).  A real scikit-sparse installed in site-packages is found before this face (the editable
install's finder comes after the standard path finder), so installing it needs no change here.
The package never imports this module.
"""
