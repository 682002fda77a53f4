

def test_ik_on_a_seven_joint_arm_without_closed_form(models) -> None:
    """Panda (imported, 7 joints, no closed form): nearby seeds always converge."""
    from kin_reference import ARM_DIR
    from controller.kinematics import load_model
    panda = load_model(ARM_DIR / "panda.toml")
    data = KinematicData(panda)
    rng = np.random.default_rng(11)
    Q = panda.random_configurations(100, rng)
    for q in Q:
        seed = np.clip(q + rng.uniform(-0.3, 0.3, 7), panda.q_min, panda.q_max)
        result = solve_ik(panda, data, fk(panda, data, q), seed)
        assert result.success, result.message
