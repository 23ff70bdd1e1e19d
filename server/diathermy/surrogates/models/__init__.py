"""CNN models shipped with the package: ``cnn_<nz>x<ny>x<nx>.pt`` and its metrics ``.json``.

Trained by ``scripts/train_default_model.sh``; ``surrogates.backend.default_model_path`` finds
the one for a scene's grid.
"""
