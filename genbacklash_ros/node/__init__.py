"""The node logic that every transport and bag replay share.

Messages, parameters, the sample rule, stream health, the pipeline, checkpoints.
"""
