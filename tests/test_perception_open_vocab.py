"""Open-vocabulary backends on tiny random transformers models built in code (no hub, no weights).

Random weights give random boxes, so these tests check plumbing: local-only loading, box
coordinates in original-image pixels, box -> mask -> track -> cloud, and the error for a missing
weights folder. Accuracy is the job of real checkpoints.
"""

import re

import numpy as np
import pytest

from lano3dp.geometry import PinholeCamera
from lano3dp.perception import (
    MissingWeightsError,
    ObjectNotFoundError,
    ObjectObserver,
    Segmenter,
    SimOracleSegmenter,
)
from lano3dp.perception.open_vocab import (
    Detection,
    GroundingDinoDetector,
    OpenVocabSegmenter,
    Owlv2Detector,
    SamBoxSegmenter,
    box_iou,
    non_max_suppression,
)
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera
from lano3dp.perception.tracker import TrackingSegmenter, VideoTracker

torch = pytest.importorskip("torch")
transformers = pytest.importorskip("transformers")

WORDS = ["red", "blue", "green", "cup", "bowl", "pan"]
# A non-square image whose size differs from every model's input size (128), so scaling errors show.
HEIGHT, WIDTH = 96, 160


def scene():
    camera = PinholeCamera.from_fovy(WIDTH, HEIGHT, 50.0, top_down_camera(96).cam_to_world)
    return render_boxes(
        camera,
        [
            Box("red_bowl", (0.10, 0.05), (0.10, 0.10, 0.06), {"kind": "bowl", "color": "red"}),
            Box("pan", (-0.15, -0.05), (0.15, 0.12, 0.04), {"kind": "pan"}),
        ],
    )


def build_grounding_dino():
    from transformers import (
        BertTokenizerFast,
        GroundingDinoConfig,
        GroundingDinoForObjectDetection,
        GroundingDinoProcessor,
        SwinConfig,
    )
    from transformers.models.grounding_dino.image_processing_pil_grounding_dino import (
        GroundingDinoImageProcessorPil,
    )

    vocab = ["[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]", ".", *WORDS]
    tokenizer = BertTokenizerFast(vocab={w: i for i, w in enumerate(vocab)})  # not vocab_file= (ignored in 5.x)
    image_processor = GroundingDinoImageProcessorPil(size={"shortest_edge": 128, "longest_edge": 128})
    torch.manual_seed(0)
    config = GroundingDinoConfig(
        backbone_config=SwinConfig(
            window_size=7, embed_dim=8, depths=[1] * 4, num_heads=[1] * 4, image_size=128, out_indices=[2, 3, 4]
        ),
        text_config={
            "model_type": "bert",
            "hidden_size": 8,
            "num_hidden_layers": 1,
            "num_attention_heads": 2,
            "intermediate_size": 8,
            "max_position_embeddings": 32,
            "vocab_size": len(vocab),
        },
        d_model=32,
        encoder_layers=1,
        decoder_layers=2,
        encoder_attention_heads=4,
        decoder_attention_heads=4,
        encoder_ffn_dim=32,
        decoder_ffn_dim=32,
        num_queries=20,
        encoder_n_points=2,
        decoder_n_points=2,
        max_text_len=32,
    )
    processor = GroundingDinoProcessor(image_processor=image_processor, tokenizer=tokenizer)
    return GroundingDinoForObjectDetection(config).eval(), processor


def build_owlv2():
    from transformers import CLIPTokenizer, Owlv2Config, Owlv2ForObjectDetection, Owlv2Processor
    from transformers.models.owlv2.image_processing_pil_owlv2 import Owlv2ImageProcessorPil

    vocab, merges = {"!": 0}, []  # id 0 must not be a real query start: OWL treats it as padding
    for c in "abcdefghijklmnopqrstuvwxyz":
        vocab.setdefault(c, len(vocab))
        vocab.setdefault(c + "</w>", len(vocab))
    for word in WORDS:
        pieces = [*word[:-1], word[-1] + "</w>"]
        current = pieces[0]
        for piece in pieces[1:]:
            if (current, piece) not in merges:
                merges.append((current, piece))
            current += piece
            vocab.setdefault(current, len(vocab))
    sot, eot = len(vocab), len(vocab) + 1
    vocab |= {"<|startoftext|>": sot, "<|endoftext|>": eot}
    tokenizer = CLIPTokenizer(vocab=vocab, merges=merges)
    processor = Owlv2Processor(
        image_processor=Owlv2ImageProcessorPil(size={"height": 128, "width": 128}), tokenizer=tokenizer
    )
    torch.manual_seed(0)
    config = Owlv2Config(
        projection_dim=32,
        text_config=dict(
            vocab_size=len(vocab),
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=1,
            num_attention_heads=2,
            max_position_embeddings=16,
            bos_token_id=sot,
            eos_token_id=eot,
            pad_token_id=eot,
        ),
        vision_config=dict(
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=1,
            num_attention_heads=2,
            image_size=128,
            patch_size=16,
        ),
    )
    return Owlv2ForObjectDetection(config).eval(), processor


def build_sam():
    from transformers import SamConfig, SamModel, SamProcessor
    from transformers.models.sam.image_processing_pil_sam import SamImageProcessorPil

    torch.manual_seed(0)
    config = SamConfig(
        vision_config=dict(
            hidden_size=32,
            output_channels=32,
            num_hidden_layers=2,
            num_attention_heads=2,
            image_size=128,
            patch_size=16,
            window_size=4,
            global_attn_indexes=[1],
            mlp_dim=64,
            num_pos_feats=16,
        ),
        prompt_encoder_config=dict(hidden_size=32, image_size=128, patch_size=16, mask_input_channels=4),
        mask_decoder_config=dict(
            hidden_size=32, mlp_dim=64, num_hidden_layers=2, num_attention_heads=2, iou_head_hidden_dim=32
        ),
    )
    processor = SamProcessor(
        image_processor=SamImageProcessorPil(size={"longest_edge": 128}, pad_size={"height": 128, "width": 128})
    )
    return SamModel(config).eval(), processor


def build_sam2_video():
    from transformers import Sam2HieraDetConfig, Sam2VideoConfig, Sam2VideoModel, Sam2VisionConfig

    torch.manual_seed(0)
    # Hidden constraints of tiny SAM2-video configs (transformers 5.23): memory encoder output 64,
    # hidden sizes > 64, no global-attention block first in a stage.
    vision = Sam2VisionConfig(
        backbone_config=Sam2HieraDetConfig(
            hidden_size=12,
            image_size=128,
            patch_kernel_size=7,
            patch_stride=4,
            patch_padding=3,
            blocks_per_stage=[1, 1, 2, 1],
            embed_dim_per_stage=[12, 24, 48, 96],
            num_attention_heads_per_stage=[1] * 4,
            global_attention_blocks=[3],
        ),
        backbone_channel_list=[96, 48, 24, 12],
        backbone_feature_sizes=[[32, 32], [16, 16], [8, 8]],
        fpn_hidden_size=128,
    )
    config = Sam2VideoConfig(
        vision_config=vision,
        image_size=128,
        num_maskmem=3,
        prompt_encoder_config=dict(hidden_size=128, image_size=128, patch_size=16, mask_input_channels=8),
        mask_decoder_config=dict(
            hidden_size=128, mlp_dim=64, num_hidden_layers=2, num_attention_heads=4, iou_head_hidden_dim=32
        ),
        memory_attention_hidden_size=128,
        memory_attention_num_layers=1,
        memory_attention_feed_forward_hidden_size=64,
        memory_attention_rope_feat_sizes=[8, 8],
        memory_encoder_hidden_size=128,
        memory_encoder_output_channels=64,
        mask_downsampler_embed_dim=128,
        memory_fuser_embed_dim=128,
        memory_fuser_intermediate_dim=64,
        max_object_pointers_in_encoder=4,
    )
    return Sam2VideoModel(config).eval()


def save(tmp_path_factory, name, model, processor=None):
    folder = tmp_path_factory.mktemp(name)
    model.save_pretrained(folder)
    if processor is not None:
        processor.save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    """Tiny random models saved to folders, as a user's local checkpoints would be."""
    return {
        "grounding_dino": save(tmp_path_factory, "gdino", *build_grounding_dino()),
        "owlv2": save(tmp_path_factory, "owlv2", *build_owlv2()),
        "sam": save(tmp_path_factory, "sam", *build_sam()),
        "sam2_video": save(tmp_path_factory, "sam2", build_sam2_video()),
    }


@pytest.mark.parametrize(
    "load", [GroundingDinoDetector.from_pretrained, Owlv2Detector.from_pretrained, SamBoxSegmenter.from_pretrained,
             VideoTracker.from_pretrained],
)  # fmt: skip
def test_missing_weights_folder_is_named(tmp_path, load):
    missing = tmp_path / "no_such_model"
    expected = re.escape(f"not found at '{missing}'") + ".*never downloaded"
    with pytest.raises(MissingWeightsError, match=expected) as info:
        load(missing)
    assert info.value.path == str(missing) and isinstance(info.value, FileNotFoundError)
    with pytest.raises(MissingWeightsError, match="no config.json"):
        load(tmp_path)


def test_grounding_dino_boxes_are_in_original_image_pixels(weights):
    detector = GroundingDinoDetector.from_pretrained(weights["grounding_dino"], box_threshold=0.0)
    frame = scene()
    scores, boxes = detector.phrase_scores(frame.rgb, ["red bowl", "pan"])
    assert scores.shape == (2, 20) and boxes.shape == (20, 4)
    # Same boxes as the library's post-processing, which scales by the original (H, W).
    inputs = detector.processor(images=frame.rgb, text="red bowl. pan.", return_tensors="pt")
    with torch.inference_mode():
        outputs = detector.model(**inputs)
    (reference,) = detector.processor.post_process_grounded_object_detection(
        outputs, inputs.input_ids, threshold=0.0, text_threshold=0.0, target_sizes=[(HEIGHT, WIDTH)]
    )
    np.testing.assert_allclose(boxes, reference["boxes"].numpy(), atol=1e-3)
    detections = detector.detect(frame.rgb, ["red bowl", "pan"])
    assert [d.phrase for d in detections] == ["red bowl", "pan"]
    for d in detections:
        assert d.box.dtype == np.float32 and 0 <= d.box[0] <= d.box[2] <= WIDTH and 0 <= d.box[1] <= d.box[3] <= HEIGHT
        assert 0.0 <= d.score <= 1.0
    detector.box_threshold = 1.01
    assert detector.detect(frame.rgb, ["red bowl", "pan"]) == [None, None]


def test_owlv2_boxes_are_clipped_to_the_image(weights):
    detector = Owlv2Detector.from_pretrained(weights["owlv2"], box_threshold=0.0)
    frame = scene()
    detections = detector.detect(frame.rgb, ["red bowl", "blue cup", "pan"])
    assert [d.phrase for d in detections] == ["red bowl", "blue cup", "pan"]
    for d in detections:
        assert 0 <= d.box[0] <= d.box[2] <= WIDTH and 0 <= d.box[1] <= d.box[3] <= HEIGHT
    detector.box_threshold = 1.01
    assert detector.detect(frame.rgb, ["pan"]) == [None]


def test_sam_masks_match_the_image_and_stay_near_their_boxes(weights):
    segmenter = SamBoxSegmenter.from_pretrained(weights["sam"], clip_margin=0.1)
    frame = scene()
    boxes = np.array([[20.0, 10.0, 60.0, 50.0], [100.0, 40.0, 150.0, 90.0]], dtype=np.float32)
    masks, scores = segmenter.masks_from_boxes(frame.rgb, boxes)
    assert masks.shape == (2, HEIGHT, WIDTH) and masks.dtype == np.bool_ and scores.shape == (2,)
    rows, cols = np.nonzero(masks[0])
    assert cols.size == 0 or (cols.min() >= 20 - 6 - 1 and cols.max() <= 60 + 6 and rows.max() <= 50 + 6)
    segmenter.clip_margin = None
    raw, _ = segmenter.masks_from_boxes(frame.rgb, boxes)
    assert np.all(raw >= masks) and raw.sum() > masks.sum()  # clipping only removes spill
    empty, empty_scores = segmenter.masks_from_boxes(frame.rgb, np.zeros((0, 4)))
    assert empty.shape == (0, HEIGHT, WIDTH) and empty_scores.shape == (0,)


class BoxFiller:
    """A deterministic stand-in for SAM: the mask is the box itself."""

    def masks_from_boxes(self, rgb, boxes):
        masks = np.zeros((len(boxes), *rgb.shape[:2]), dtype=bool)
        for m, (x0, y0, x1, y1) in enumerate(np.round(boxes).astype(int)):
            masks[m, y0:y1, x0:x1] = True
        return masks, np.ones(len(boxes), dtype=np.float32)


def test_open_vocab_chain_box_to_mask_to_cloud(weights):
    detector = GroundingDinoDetector.from_pretrained(weights["grounding_dino"], box_threshold=0.0)
    frame = scene()
    segmenter = OpenVocabSegmenter(detector, BoxFiller())
    assert isinstance(segmenter, Segmenter)
    results = segmenter.segment(frame, ["red bowl", "pan"])
    for result, detection in zip(results, segmenter.last_detections, strict=True):
        x0, y0, x1, y1 = np.round(detection.box).astype(int)
        assert result.found and result.score == detection.score and result.pixel_count == (x1 - x0) * (y1 - y0)
    clouds = ObjectObserver(segmenter, n_points=64, min_points=1).observe(frame, ["red bowl", "pan"])
    assert clouds.points.shape == (2, 64, 3) and np.all(np.isfinite(clouds.points))
    # With the real (tiny) SAM the chain runs the same way; random weights decide what is found.
    real = OpenVocabSegmenter.from_pretrained(weights["grounding_dino"], weights["sam"], box_threshold=0.0)
    for result in real.segment(frame, ["red bowl", "pan"]):
        assert (result.mask is not None) == result.found and (not result.found or result.mask.shape == (HEIGHT, WIDTH))


def test_open_vocab_miss_is_explicit_and_reaches_the_observer(weights):
    detector = GroundingDinoDetector.from_pretrained(weights["grounding_dino"], box_threshold=1.01)
    segmenter = OpenVocabSegmenter(detector, BoxFiller())
    (result,) = segmenter.segment(scene(), ["red bowl"])
    assert not result.found and result.mask is None
    with pytest.raises(ObjectNotFoundError, match="'pan' was not found"):
        ObjectObserver(segmenter).observe(scene(), ["pan"])


def test_video_tracker_follows_seeded_masks_with_bounded_memory(weights):
    tracker = VideoTracker.from_pretrained(weights["sam2_video"], keep_frames=2)
    frame = scene()
    seeds = {r.phrase: r.mask for r in SimOracleSegmenter().segment(frame, ["red bowl", "pan"])}
    first = tracker.start(frame.rgb, seeds)
    assert list(first) == ["red bowl", "pan"]
    for _ in range(5):
        tracked = tracker.track(frame.rgb)
        assert list(tracked) == ["red bowl", "pan"]
        for item in tracked.values():
            assert 0.0 <= item.score <= 1.0
            assert item.mask is None or (item.mask.shape == (HEIGHT, WIDTH) and item.mask.dtype == np.bool_)
    # The conditioning frame plus the last keep_frames + 1 frames; older ones are dropped.
    assert sorted(tracker._session.processed_frames) == [0, 3, 4, 5]
    with pytest.raises(ValueError, match="session started at"):
        tracker.track(np.zeros((32, 32, 3), np.uint8))
    tracker.reset()
    with pytest.raises(RuntimeError, match="call start"):
        tracker.track(frame.rgb)
    with pytest.raises(ValueError, match="non-empty"):
        tracker.start(frame.rgb, {"pan": np.zeros((HEIGHT, WIDTH), bool)})


class ScriptedTracker:
    """Duck-typed VideoTracker whose objects are lost on the frames listed in `lost_on`."""

    def __init__(self, lost_on=()):
        self.lost_on = set(lost_on)
        self.started = False
        self.frames = 0
        self.starts = 0

    def start(self, rgb, masks):
        self.started, self.masks, self.starts = True, dict(masks), self.starts + 1

    def track(self, rgb):
        from lano3dp.perception.tracker import TrackedMask

        self.frames += 1
        lost = self.frames in self.lost_on
        return {name: TrackedMask(None if lost else mask, 0.0 if lost else 0.9) for name, mask in self.masks.items()}

    def reset(self):
        self.started = False


class CountingOracle(SimOracleSegmenter):
    calls = 0

    def segment(self, frame, phrases):
        self.calls += 1
        return super().segment(frame, phrases)


def test_tracking_segmenter_detects_once_tracks_and_redetects_when_lost():
    frame = scene()
    initial, tracker = CountingOracle(), ScriptedTracker(lost_on={3})
    segmenter = TrackingSegmenter(initial, tracker)
    results = [segmenter.segment(scene(), ["red bowl", "pan"]) for _ in range(5)]
    assert initial.calls == 2 and tracker.starts == 2 and segmenter.redetections == 1
    assert all(r.found for frame_results in results for r in frame_results)
    assert results[1][0].score == pytest.approx(0.9)  # a tracked frame
    segmenter.reset()
    segmenter.segment(frame, ["pan"])
    assert initial.calls == 3


def test_targets_and_obstacles_share_one_session_and_one_step_per_frame():
    initial, tracker = CountingOracle(), ScriptedTracker()
    segmenter = TrackingSegmenter(initial, tracker)
    first = scene()
    segmenter.segment(first, ["red bowl"])  # targets
    segmenter.segment(first, ["pan"])  # obstacles: a new phrase, detected with the targets
    assert initial.calls == 2 and set(tracker.masks) == {"red bowl", "pan"}
    for _ in range(3):
        frame = scene()
        targets = segmenter.segment(frame, ["red bowl"])
        obstacles = segmenter.segment(frame, ["pan"])
        assert targets[0].found and obstacles[0].found
    assert initial.calls == 2 and tracker.frames == 3  # one tracking step per frame, no re-detection


def test_real_tracker_behind_the_segmenter_protocol(weights):
    tracker = VideoTracker.from_pretrained(weights["sam2_video"])
    segmenter = TrackingSegmenter(SimOracleSegmenter(), tracker)
    frame = scene()
    for _ in range(3):
        results = segmenter.segment(frame, ["red bowl", "pan"])
        assert [r.phrase for r in results] == ["red bowl", "pan"]
        assert all(r.found == (r.mask is not None) for r in results)
    assert tracker.started


def test_non_max_suppression_keeps_the_best_of_overlapping_boxes():
    def det(box, score):
        return Detection("cup", np.array(box, dtype=np.float32), score)

    a, b, c = det([0, 0, 10, 10], 0.9), det([1, 0, 11, 10], 0.8), det([30, 30, 40, 40], 0.7)
    assert box_iou(a.box, b.box) == pytest.approx(90 / 110)
    assert non_max_suppression([c, b, a]) == [a, c]
    assert non_max_suppression([c, b, a], iou_threshold=0.95) == [a, b, c]


def test_every_instance_of_an_obstacle_phrase_gets_its_own_mask(weights):
    detector = GroundingDinoDetector.from_pretrained(weights["grounding_dino"], box_threshold=0.0, nms_iou=0.3)
    frame = scene()
    (all_boxes,) = detector.detect_all(frame.rgb, ["blue cup"])
    assert len(all_boxes) >= 2 and [d.score for d in all_boxes] == sorted((d.score for d in all_boxes), reverse=True)
    assert all(box_iou(p.box, q.box) < 0.3 for i, p in enumerate(all_boxes) for q in all_boxes[i + 1 :])
    best = detector.detect(frame.rgb, ["blue cup"])[0]
    assert best.score == all_boxes[0].score and np.array_equal(best.box, all_boxes[0].box)
    segmenter = OpenVocabSegmenter(detector, BoxFiller())
    instances = segmenter.segment_instances(frame, "blue cup")
    assert [r.matched_name for r in instances] == [f"blue cup#{i}" for i in range(len(instances))]
    clouds = ObjectObserver(segmenter, n_points=16, min_points=1).observe_instances(frame, ["blue cup"])
    assert clouds.points.shape[0] == len(instances) >= 1


def test_factory_builds_open_vocab_and_tracking_segmenters_from_folders(weights, tmp_path):
    from lano3dp.perception import SegmenterConfig, build_segmenter

    common = dict(detector_dir=weights["grounding_dino"], sam_dir=weights["sam"], box_threshold=0.2)
    open_vocab = build_segmenter(SegmenterConfig(kind="open_vocab", **common))
    assert isinstance(open_vocab, OpenVocabSegmenter) and open_vocab.detector.box_threshold == 0.2
    tracking = build_segmenter(SegmenterConfig(kind="tracking", tracker_dir=weights["sam2_video"], **common))
    assert isinstance(tracking, TrackingSegmenter) and isinstance(tracking.initial, OpenVocabSegmenter)
    with pytest.raises(MissingWeightsError, match="OWLv2 weights not found"):
        build_segmenter(
            SegmenterConfig(kind="open_vocab", detector="owlv2", detector_dir=tmp_path / "x", sam_dir=tmp_path)
        )
