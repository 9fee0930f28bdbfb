"""models.provenance: the record of earlier runs a fine-tune keeps, and stages read back from commands."""

from denoisebench.models.provenance import all_train_scenes, run_record, stages_from_commands

# The commands of the first shipped dpcn_small.pt (recorded before stages were): two training stages,
# then a --steps 0 command that scored the weights on another dataset.
OLD_COMMANDS = [
    "denoisebench train --model dpcn --data /tmp/models_work/data64 --config small --steps 2000 --out ck.pt "
    "--seed 0 --batch-size 8 --crop 32 --lr 0.001",
    "denoisebench train --model dpcn --data /tmp/models_work/data64 --config small --steps 1500 --out ck.pt "
    "--resume ck.pt --seed 0 --batch-size 8 --crop 32 --lr 0.001 --loss relative",
    "denoisebench train --model dpcn --data /tmp/t19/data --config small --steps 0 --out r.pt --resume w.pt "
    "--seed 0 --batch-size 8 --lr 0.001",
]


def test_stages_from_commands_of_a_checkpoint_without_stages():
    stages = stages_from_commands(OLD_COMMANDS, {"spp": [2, 4, 8]}, lambda config: "log")
    assert [(s["from_step"], s["steps"], s["loss"], s["lr"], s["lr_schedule"]) for s in stages] == [
        (0, 2000, "log", 0.001, "constant"),
        (2000, 1500, "relative", 0.001, "constant"),
    ]
    assert all(s["batch_size"] == 8 and s["crop"] == 32 and s["spp"] == [2, 4, 8] and s["threads"] == 1 for s in stages)


def test_run_record_keeps_training_commands_only_and_tags_stages_with_their_data():
    meta = {
        "commands": OLD_COMMANDS,
        "steps": 3500,
        "seconds": 720.0,
        "dataset_hash": "abc",
        "train_scenes": ["a_000"],
        "val_scenes": ["b_001"],
        "validation": {"relmse": 0.08},
        "evaluated_on": {"dataset_hash": "def"},
    }
    record = run_record(meta, "ck.pt", lambda config: "log")
    assert record["commands"] == OLD_COMMANDS[:2]  # the scoring command changed no weights
    assert [s["dataset_hash"] for s in record["stages"]] == ["abc", "abc"]
    assert record["steps"] == 3500 and record["checkpoint"] == "ck.pt" and record["validation"] == {"relmse": 0.08}
    assert all_train_scenes({"train_scenes": ["c_100"], "earlier_runs": [record]}) == {"a_000", "c_100"}
