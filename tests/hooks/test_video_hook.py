"""The training video (``eval.video_interval``, hooks/video.py): through the logger's
``log_video`` every N epochs, unsafe steps marked, off by default, changing no number."""

from __future__ import annotations

import imageio.v2 as imageio
import numpy as np
import pytest

from s3rl_torchrl.trainer import ConfigError, train, validate
from s3rl_torchrl.trainer.metrics import read_metrics

# experiment=tiny: 3 epochs of 200 frames, 50-step evaluation episodes.
ARGS = ("algo=sac_lag", "collector.total_frames=400", "eval.video_interval=1")


@pytest.mark.slow
def test_tensorboard_reads_the_video_events(tiny_config, tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    train(tiny_config(*ARGS, "logger=tensorboard"), tmp_path)
    (events,) = tmp_path.glob("logs/*/events.out.tfevents.*")
    acc = EventAccumulator(str(events.parent), size_guidance={"images": 0})
    acc.Reload()
    # TensorBoard keeps a video as an animated GIF in its image plugin, one per epoch.
    assert "eval/video" in acc.Tags()["images"]
    videos = acc.Images("eval/video")
    assert [v.step for v in videos] == [200, 400]
    gif = videos[0].encoded_image_string
    assert gif[:6] in (b"GIF87a", b"GIF89a")
    frames = imageio.mimread(gif, format="GIF")
    # The reset frame and one per step of the 50-step evaluation episode.
    assert len(frames) == 51 and frames[0].shape[:2] == (160, 160)


@pytest.mark.slow
def test_csv_logger_writes_mp4_files_into_the_run_directory(tiny_config, tmp_path):
    train(tiny_config(*ARGS, "eval.video_interval=2"), tmp_path)
    videos = sorted(tmp_path.glob("logs/*/videos/eval/video_*.mp4"))
    assert [v.name for v in videos] == ["video_400.mp4"]  # epoch 2 of 2
    frames = imageio.mimread(videos[0], format="FFMPEG")
    assert len(frames) == 51 and frames[0].shape == (160, 160, 3)
    assert np.std(frames[10]) > 0


@pytest.mark.slow
def test_wandb_offline_run_holds_the_video(tiny_config, tmp_path):
    train(tiny_config("algo=sac_lag", "collector.total_frames=200", "eval.video_interval=1",
                      "logger=wandb"), tmp_path)
    (video,) = tmp_path.glob("logs/wandb/offline-run-*/files/media/videos/eval/video_*.mp4")
    frames = imageio.mimread(video, format="FFMPEG")
    # 51 frames; W&B encodes with moviepy, whose mp4 reads back with one frame repeated.
    assert len(frames) in (51, 52) and frames[0].shape == (160, 160, 3)


def test_video_is_off_by_default_and_needs_a_logger_that_logs_it(tiny_config, compose):
    assert tiny_config().eval.video_interval == 0
    for backend in ("none", "mlflow"):
        with pytest.raises(ConfigError, match=r"eval.video_interval.*choose logger=csv"):
            validate(compose("experiment=tiny", "eval.video_interval=1", f"logger={backend}"))
    with pytest.raises(ConfigError, match=r"'eval.video_interval'"):
        validate(compose("experiment=tiny", "eval.video_interval=-1"))


def test_a_video_changes_no_number_of_the_run(tiny_config, tmp_path):
    # The video env is a copy of the test env, not the test env: evaluation is the same.
    args = ("algo=sac_lag", "collector.total_frames=200", "logger=csv")
    train(tiny_config(*args), tmp_path / "plain")
    train(tiny_config(*args, "eval.video_interval=1"), tmp_path / "video")
    plain, video = read_metrics(tmp_path / "plain"), read_metrics(tmp_path / "video")
    drop = {"eval/seconds"}  # wall time
    assert [{k: v for k, v in r.items() if k not in drop} for r in plain] == [
        {k: v for k, v in r.items() if k not in drop} for r in video
    ]
    assert list((tmp_path / "video").glob("logs/*/videos/eval/video_200.mp4"))
