/*  The processes of the hostile benchmark (experiments/bench/hostile.py).

    swipl hostile_node.pl target TOKEN
        A platform node on 127.0.0.1 (OS-chosen port) with the platform's
        default limits: the node under attack. Prints "PORT <p>" and serves
        until standard input closes.

    swipl hostile_node.pl peer TOKEN TARGET_PORT FLOATS PAUSE_MS BUDGET_S FRESH
        An authenticated peer: a node on 127.0.0.1 and an agent whose payload
        holds FLOATS floats, moved to the target and back, PAUSE_MS between
        two hops, until BUDGET_S seconds have passed. With FRESH = true the
        peer keeps no pooled connection (flag dfrl_pool_max 0), so every move
        to the target opens a new connection and passes the target's
        acceptor and admission; with false, pooled connections are reused.
        The agent uses only what the target's sandbox allows (its code
        arrives over the network): output to user_output, get_time/1,
        sleep/1, its own facts, move_agent/2. Prints "PORT <p>",
        then serves until standard input closes.

    Both processes print one line per event where it happens (epoch seconds,
    the same clock on one host):
        DEPART T0 FROM TO           a move is called at FROM
        HOP T0 T1 FROM TO           the agent's handler starts at TO
        FAIL T0 T1 FROM TO ERROR    the move raised (the agent stays at FROM);
                                    it is tried again after the pause
        DONE T                      the budget is spent (at the peer)
*/
:- use_module('../../platform_pl/tartarus').
:- use_module(library(main)).

:- initialization(main, main).

:- dynamic data/2, departed/3, plan/2.

main([target, Token0]) :-
    set_stream(user_output, buffer(line)),
    atom_number(Token0, Token),
    node_start('127.0.0.1':0, Node, [token(Token)]),
    node_property(Node, bind(_:Port)),
    emit('PORT ~w', [Port]),
    read_term(user_input, _, []),       % until stdin closes
    node_stop(Node).
main([peer, Token0, Target0, Floats0, Pause0, Budget0, Fresh]) :-
    set_stream(user_output, buffer(line)),
    maplist(atom_number, [Token0, Target0, Floats0, Pause0, Budget0],
            [Token, Target, Floats, PauseMs, Budget]),
    must_be(boolean, Fresh),
    (   Fresh == true                   % no connection is kept: each move dials anew
    ->  set_prolog_flag(dfrl_pool_max, 0)
    ;   true
    ),
    node_start('127.0.0.1':0, Node, [token(Token), reply_timeout(10), connect_timeout(5)]),
    node_property(Node, bind(_:Port)),
    emit('PORT ~w', [Port]),
    findall(F, ( between(1, Floats, I), F is I * 0.001 + 0.5 ), Data),
    get_time(Now),
    End is Now + Budget,
    Pause is PauseMs / 1000,
    assertz(data(guid, Data)),
    assertz(plan(guid, plan(Port, Target, Pause, End))),
    create_mobile_agent(hostile_bencher, ('127.0.0.1', Port), hostile_hop, [Token]),
    add_payload(hostile_bencher, [(data,2), (plan,2), (departed,3)]),
    execute_agent(hostile_bencher, ('127.0.0.1', Port), hostile_hop),
    read_term(user_input, _, []),
    node_stop(Node).

emit(Format, Args) :-
    format(user_output, Format, Args),
    nl(user_output),
    flush_output(user_output).

%   The agent: log the arrival, then (until the budget is spent) pause and
%   move on; a move that fails is logged and tried again after the pause.
%   Its lines go to user_output, line-buffered by both processes' main/1.
hostile_hop(guid, (_, Here), main) :-
    get_time(Now),
    (   retract(departed(guid, T0, From))
    ->  format(user_output, 'HOP ~6f ~6f ~w ~w~n', [T0, Now, From, Here])
    ;   true
    ),
    plan(guid, plan(Peer, Target, Pause, End)),
    (   Here =:= Peer -> Next = Target ; Next = Peer ),
    between(1, 1000000, _),
    get_time(T),
    (   T > End, Here =:= Peer
    ->  format(user_output, 'DONE ~6f~n', [T])
    ;   sleep(Pause),
        get_time(T1),
        assertz(departed(guid, T1, Here)),
        format(user_output, 'DEPART ~6f ~w ~w~n', [T1, Here, Next]),
        catch(move_agent(guid, ('127.0.0.1', Next)), E, true),
        (   var(E)
        ->  true
        ;   retractall(departed(guid, _, _)),
            get_time(T2),
            format(string(Why), '~q', [E]),
            split_string(Why, "\n", " ", Parts),
            atomic_list_concat(Parts, ' ', Flat),
            format(user_output, 'FAIL ~6f ~6f ~w ~w ~w~n', [T1, T2, Here, Next, Flat]),
            fail
        )
    ),
    !.
