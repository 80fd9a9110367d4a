"""1D SURF horizon landmarks (Anderson et al., "Robot Localisation Using Natural Landmarks").

A robot moving on a plane sees landmarks slide along its horizon without rotating or leaving it. One band of pixels
around the horizon, summed vertically and sampled every 4 columns, becomes a 1D signal; 1D SURF finds
blob-like features in it and describes each with 6 numbers; matching two horizons gives a recognition score and
the line x_test = b_s * x_stored + b_d that tells how the robot turned (b_d) and moved closer or away (b_s).

    from loops.horizon import HorizonParams, extract_features, match, LandmarkMemory

    params = HorizonParams()                      # the paper's defaults; HorizonParams.preset("paper")
    stored = extract_features(image_a, row=183, params=params)
    test = extract_features(image_b, row=183, params=params)
    result = match(test, stored, params)          # .score, .score_ransac, .b_s, .b_d, .inliers
"""
from loops.horizon.bands import BandsMatch, band_rows, extract_bands, match_bands
from loops.horizon.matching import MatchResult, fit_line_ransac, match, nn_matches
from loops.horizon.memory import (
                                  MEMORY_VERSION,
                                  Landmark,
                                  LandmarkMemory,
                                  MemoryFormatError,
                                  Recognition,
                                  load_memory,
                                  save_memory,
)
from loops.horizon.packed import (
                                  PackedBands,
                                  PackedMatch,
                                  PackedScores,
                                  PackedSet,
                                  extract_packed,
                                  match_packed,
                                  stack_packed,
                                  uses_packed,
)
from loops.horizon.params import PRESETS, Consensus, HorizonParams, SampleMode
from loops.horizon.recognizer import HorizonRecognizer, HorizonVerifier
from loops.horizon.signal import HorizonError, HorizonLine, horizon_signal, sample_columns
from loops.horizon.surf1d import HorizonFeatures, detect_and_describe, extract_features, lobe_sizes, responses
from loops.horizon.views import HorizonMatch, HorizonView, extract_view, match_views, score_views

__all__ = [
    "BandsMatch", "Consensus", "HorizonMatch", "HorizonView", "PackedBands", "PackedMatch", "PackedScores",
    "PackedSet", "extract_packed", "extract_view", "match_packed", "match_views", "score_views", "stack_packed",
    "uses_packed", "band_rows", "extract_bands", "match_bands", "HorizonError", "HorizonFeatures", "HorizonLine", "HorizonParams", "HorizonRecognizer", "HorizonVerifier",
    "Landmark", "LandmarkMemory", "MEMORY_VERSION", "MatchResult", "MemoryFormatError", "PRESETS", "Recognition",
    "SampleMode", "detect_and_describe", "extract_features", "fit_line_ransac", "horizon_signal", "load_memory",
    "lobe_sizes", "match", "nn_matches", "responses", "sample_columns", "save_memory",
]
