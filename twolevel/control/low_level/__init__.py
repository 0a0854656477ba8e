"""The low level: the paper's runtime monitor that checks the MPC's plan on the detailed model
and corrects it. ``controller`` (one step end to end), ``settings``, ``rules`` (the rules as it
judges them; which allow screening), ``prediction`` (rollouts of the detailed model), ``judge``
(signals and the batched monitor), ``sampling`` (the ball around u*), ``screening`` (on
prefixes), ``brake`` (full brake, least violation), ``decision``. Import from the modules; this
package imports nothing."""
