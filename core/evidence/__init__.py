"""Per-frame image features (algorithms.md 7.2-7.4, 7.7): silhouettes by background subtraction, distance
maps, Sobel edges and edge-enhancing-diffused CIELab a,b. NumPy, SciPy and OpenCV only."""
from .background import BackgroundModel
from .diffusion import diffusion_explicit_reference, edge_enhancing_diffusion
from .errors import FeatureInputError
from .mask_cleanup import clean_silhouette, silhouette_iou
from .view_features import ViewFeatures, compute_view_features, distance_to_mask, lab_ab, sobel_edges

__all__ = ["BackgroundModel", "ViewFeatures", "compute_view_features", "edge_enhancing_diffusion",
           "diffusion_explicit_reference", "silhouette_iou", "clean_silhouette", "distance_to_mask",
           "sobel_edges", "lab_ab", "FeatureInputError"]
