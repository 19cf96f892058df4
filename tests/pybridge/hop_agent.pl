% A Tartarus-style agent program for test_bridge_platform.py: started on one
% platform, it moves to the robot's platform (user:robot_port/1), reads the
% robot's Q-table, writes it back plus 1.0 and records the sum it read.
:- dynamic hop/3.

hop(guid, (Ip, Port), main) :-
    user:robot_port(Robot),
    (   Port == Robot
    ->  get_qtable(r1, qtable(S, V)),
        maplist([X, Y]>>(Y is X + 1.0), V, V2),
        set_qtable(r1, qtable(S, V2)),
        sum_list(V, Sum),
        assertz(user:agent_done(guid, Port, Sum))
    ;   move_agent(guid, (Ip, Robot))
    ).
