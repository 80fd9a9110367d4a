"""Place recognition and loop detection for a robot's camera.

Three recognisers under one contract (loops.recognition: observe, add, query -> ranked candidates; a separate
geometric verifier), combined with one acceptance policy by loops.loop_detector:

    loops.cdvs      compact descriptors in the spirit of MPEG CDVS (a few kB per keyframe, any camera)
    loops.vocab     vocabulary-tree bag of words (visual-memory localisation; a floor vocabulary ships in data/)
    loops.horizon   1D SURF features of the horizon (forward-looking cameras on a plane)

Shared kernels: loops.hamming (binary descriptor distances), loops.geometry (image-plane transforms and their
RANSAC, on the loop of odometry.shared.ransac), loops.curves (ROC, precision-recall). Errors derive from
loops.errors.LoopsError.
"""
