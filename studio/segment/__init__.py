"""Segmentation: HSV background model, background / person / shadow classification,
morphology, multi-view shadow voting and the skin classifier (thesis §5.5, §6.3.4).

>>> from studio.segment import BackgroundModel, vote_shadows, SkinClassifier
"""

from studio.segment.adaptive import AdaptiveSettings, learn_tint
from studio.segment.background import BackgroundModel
from studio.segment.classify import BACKGROUND, PERSON, SHADOW, Thresholds, classify_pixels
from studio.segment.errors import SegmentationError
from studio.segment.hsv import circular_mean, circular_std, hue_distance, rgb_to_hsv
from studio.segment.metrics import binary_scores, tune_thresholds
from studio.segment.morphology import STUDIO_MORPHOLOGY, Morphology, clean_labels, fill_holes, remove_small_components
from studio.segment.self_shadow import StreamFrame, StreamShadows, learn_stream_shadows, stream_frame
from studio.segment.session import SegmentOptions, SegmentationSummary, segment_session
from studio.segment.shadow_geometry import learn_shadow_direction, shadow_geometry
from studio.segment.skin import SkinClassifier, ycrcb_skin
from studio.segment.static import StaticDetector, StaticSettings, ignore_masks
from studio.segment.voting import FloorVotes, ShadowVoter, VotingResult, encode_ratio, floor_vote_image, vote_shadows

__all__ = [
    "AdaptiveSettings",
    "BACKGROUND",
    "PERSON",
    "SHADOW",
    "BackgroundModel",
    "FloorVotes",
    "Morphology",
    "STUDIO_MORPHOLOGY",
    "SegmentOptions",
    "SegmentationError",
    "SegmentationSummary",
    "ShadowVoter",
    "SkinClassifier",
    "StaticDetector",
    "StaticSettings",
    "StreamFrame",
    "StreamShadows",
    "Thresholds",
    "VotingResult",
    "binary_scores",
    "circular_mean",
    "circular_std",
    "classify_pixels",
    "clean_labels",
    "encode_ratio",
    "fill_holes",
    "floor_vote_image",
    "hue_distance",
    "ignore_masks",
    "learn_shadow_direction",
    "learn_stream_shadows",
    "learn_tint",
    "remove_small_components",
    "rgb_to_hsv",
    "segment_session",
    "shadow_geometry",
    "stream_frame",
    "tune_thresholds",
    "vote_shadows",
    "ycrcb_skin",
]
