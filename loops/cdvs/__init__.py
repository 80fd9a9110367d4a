"""Compact-descriptor loop detection in the spirit of MPEG CDVS (seed 001 §II-III).

    from loops.cdvs import encode, decode, match, LoopDatabase, LoopModel, CdvsParams

    data = encode(gray_image, mode=4, params=CdvsParams.floor(4))   # <= 4096 bytes
    d = decode(data)                                               # Descriptor: keypoints, local, global
    r = match(d, other)                                            # global_score, local_score, inlier pairs
    db = LoopDatabase(4, CdvsParams.floor(4), model=LoopModel.default())
    cands = db.query(d, frame_id); db.add(frame_id, d)
"""
from loops.cdvs.codec import (
                              Descriptor,
                              DescriptorDecodeError,
                              decode,
                              encode,
                              encode_all_modes,
                              encode_features,
                              extract,
)
from loops.cdvs.database import Candidate, DatabaseParams, LoopDatabase
from loops.cdvs.extract import Features, extract_features
from loops.cdvs.match import IncompatibleDescriptorsError, MatchResult, match
from loops.cdvs.model import LoopModel
from loops.cdvs.params import BUDGETS, MODES, CdvsParams, ExtractionParams, GeometryModel, MatchParams, ModeParams
from loops.cdvs.recognizer import CdvsRecognizer, CdvsVerifier
from loops.cdvs.trained import TrainedParams, load_trained

__all__ = ["BUDGETS", "MODES", "Candidate", "CdvsParams", "CdvsRecognizer", "CdvsVerifier", "DatabaseParams",
           "Descriptor", "DescriptorDecodeError", "ExtractionParams", "Features", "GeometryModel",
           "IncompatibleDescriptorsError", "LoopDatabase", "LoopModel", "MatchParams", "MatchResult", "ModeParams",
           "TrainedParams", "decode", "encode", "encode_all_modes", "encode_features", "extract", "extract_features",
           "load_trained", "match"]
