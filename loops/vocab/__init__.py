"""Visual-memory localisation with a vocabulary-tree bag of words (kidnapped robot).

    from loops.vocab import VisualMemory, preset
    memory = VisualMemory.build(key_images, key_names, preset("default", descriptor="briefrot"))
    ranking = memory.query(image)           # ranking.keys (indices into memory.key_names), ranking.scores
    memory.save("corridor.vmem"); VisualMemory.load("corridor.vmem")

Method and metrics: Aldana-Murillo, Hayet, Becerra, "Comparison of local descriptors for humanoid robots
localization using a visual bag of words approach" (hierarchical vocabulary of Nister & Stewenius, TF-IDF,
inverted index, chi-square; BRIEF, BRIEFROT, ORB, SURF, colour vocabularies; mu1 / mu2).
"""
from .database import BowDatabase, EmptyMemoryError, Scores, similarity_dense
from .evaluate import Evaluation, QueryResult, evaluate, evaluate_descriptors, score_rankings
from .features import GrayscaleImageError, NoFeaturesError, brief_angles, extract, extraction_key, is_grayscale
from .fileformat import VocabFileError, load_arrays, save_arrays
from .floor_vocabulary import load_floor_vocabulary
from .kinds import DescriptorKind
from .memory import Ranking, VisualMemory, merge_max, vocabulary_seed
from .metrics import Summary, full_ranks, mu1, mu2, recall_at, repeatability
from .params import PRESETS, DescriptorName, Distance, VocabParams, preset
from .recognizer import VerifyParams, VocabObservation, VocabRecognizer, VocabVerifier
from .tree import VocabularyTree, build_tree, load_vocabulary, save_vocabulary

__all__ = [
    "BowDatabase", "DescriptorKind", "DescriptorName", "Distance", "EmptyMemoryError", "Evaluation",
    "GrayscaleImageError", "NoFeaturesError", "PRESETS", "QueryResult", "Ranking", "Scores", "Summary",
    "VerifyParams", "VisualMemory", "VocabFileError", "VocabObservation", "VocabParams", "VocabRecognizer",
    "VocabVerifier", "VocabularyTree", "brief_angles", "build_tree", "evaluate", "evaluate_descriptors", "extract",
    "extraction_key", "full_ranks", "is_grayscale", "load_arrays", "load_floor_vocabulary", "load_vocabulary",
    "merge_max", "mu1", "mu2", "preset", "recall_at", "repeatability", "save_arrays", "save_vocabulary",
    "score_rankings", "similarity_dense", "vocabulary_seed",
]
