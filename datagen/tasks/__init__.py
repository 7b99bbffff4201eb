"""The engine's tasks, one module each with its env glue and its expert (MimicGen's env_interfaces/):
each registers its task as it is imported (datagen.task.register), and datagen.task.known_tasks() imports
every module here, so a new task is one module in this folder, listed nowhere else (docs/adding-a-task.md).

aloha                 our ALOHA cube handoff (aloha_env.py, scripted_expert.AlohaExpert)
pusht                 our PushT (pusht_env.py, scripted_expert.PushTExpert, written over a batch of lanes)
fast_experts          AlohaExpert over a batch of lanes (the same bits)
fast_pusht            PushT's lanes in one MjData
gym_pusht             LeRobot's gym-pusht, pixels; gym_pusht_expert its expert
pusher                Gymnasium's 7-DoF Pusher-v5, in SE(3); pusher_expert its controller and expert
aloha_transfer_cube   gym-aloha's ViperX transfer-cube; aloha_insertion its insertion; aloha_sim the two
                      scenes through our mujoco, aloha_sim_expert their expert
"""
