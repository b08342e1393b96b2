class HipPD:
    """Hold each leg at +-target from the torso: u = -kp (q_hip -+ target) - kd dq_hip."""

    def __init__(self, model, kp=5.0, kd=1.0, target=0.3):
        self.model, self.kp, self.kd, self.target = model, kp, kd, target

    def __call__(self, t, q, dq, stance_leg):
        return [-self.kp * (q[2] - self.target) - self.kd * dq[2],
                -self.kp * (q[3] + self.target) - self.kd * dq[3]]
