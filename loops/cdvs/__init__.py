"""Compact-descriptor loop detection in the spirit of MPEG CDVS (seed 001 §II-III).

    from loops.cdvs import encode, decode, match, LoopDatabase, LoopModel
"""
from loops.cdvs.codec import (Descriptor, DescriptorDecodeError, decode, encode, encode_all_modes, encode_features,
                              extract)
from loops.cdvs.extract import Features, extract_features
from loops.cdvs.match import IncompatibleDescriptorsError, MatchResult, match
from loops.cdvs.params import BUDGETS, MODES, CdvsParams, ExtractionParams, GeometryModel, MatchParams, ModeParams
from loops.cdvs.trained import TrainedParams, load_trained

__all__ = ["BUDGETS", "MODES", "CdvsParams", "Descriptor", "DescriptorDecodeError", "ExtractionParams", "Features",
           "GeometryModel", "IncompatibleDescriptorsError", "MatchParams", "MatchResult", "ModeParams",
           "TrainedParams", "decode", "encode", "encode_all_modes", "encode_features", "extract", "extract_features", "load_trained",
           "match"]
