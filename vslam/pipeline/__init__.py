"""The SLAM pipeline: `Pipeline(config).run(sequence)` -> `PipelineResult`; `step()` per frame for online use."""
from vslam.pipeline.config import KeyframePolicy, LoopConfig, PipelineConfig, RecordingConfig, VocabLoopConfig
from vslam.pipeline.pipeline import FrameOutput, LoopRecord, Pipeline, PipelineResult

__all__ = ["FrameOutput", "KeyframePolicy", "LoopConfig", "LoopRecord", "Pipeline", "PipelineConfig",
           "PipelineResult", "RecordingConfig", "VocabLoopConfig"]
