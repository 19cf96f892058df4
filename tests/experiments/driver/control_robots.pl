/*  Robots with in-memory tables for the control tests: a plain-Prolog host
    of the resource hook (platform_pl/robot_resources.pl, contract C1).
    Consult it into a node (node_main.pl --consult) after the dFRL agent.
    Robots r1..r4 have 2x2 tables; robot Rn starts with every value n.
*/
:- multifile robot_resources:robot/2, robot_resources:table_get/3,
             robot_resources:tables_get/4, robot_resources:table_set/3.
:- dynamic control_table/2.

control_table(r1, qtable([2, 2], [1.0, 1.0, 1.0, 1.0])).
control_table(r2, qtable([2, 2], [2.0, 2.0, 2.0, 2.0])).
control_table(r3, qtable([2, 2], [3.0, 3.0, 3.0, 3.0])).
control_table(r4, qtable([2, 2], [4.0, 4.0, 4.0, 4.0])).

robot_resources:robot(R, [algo(qlearning), shape(S)]) :-
    control_table(R, qtable(S, _)).
robot_resources:table_get(R, T, _) :-
    control_table(R, T).
robot_resources:tables_get(R, qtable(S, V), qtable(S, W), _) :-
    control_table(R, qtable(S, V)),
    maplist([_, 1.0]>>true, V, W).
robot_resources:table_set(R, T, _) :-
    retract(control_table(R, _)),
    assertz(control_table(R, T)).
