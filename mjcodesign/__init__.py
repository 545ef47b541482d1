"""mjcodesign: co-design of tendon-driven soft grippers on MuJoCo."""
