"""The cushion: a NURBS surface whose face-side row follows the seal on the patient."""
