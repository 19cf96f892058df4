/*  The processes of the hostile benchmark (experiments/bench/hostile.py).

    swipl hostile_node.pl target TOKEN
        A platform node on 127.0.0.1 (OS-chosen port) with the platform's
        default limits: the node under attack. Prints "PORT <p>" and serves
        until standard input closes.

    swipl hostile_node.pl peer TOKEN TARGET_PORT FLOATS PAUSE_MS BUDGET_S FRESH
        An authenticated peer: a node on 127.0.0.1 and an agent whose payload
        holds FLOATS floats, moved to the target and back, PAUSE_MS between
        two hops, until BUDGET_S seconds have passed. With FRESH = true every
        move to the target opens a new connection (the transport's pool is
        dropped first), so each hop passes the target's acceptor and its
        admission; with false, pooled connections are reused. Prints "PORT <p>",
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
:- use_module('../../platform_pl/transport', [transport_drop_pool/0]).
:- use_module(library(main)).

:- initialization(main, main).

:- dynamic data/2, departed/3, plan/2.

main([target, Token0]) :-
    atom_number(Token0, Token),
    node_start('127.0.0.1':0, Node, [token(Token)]),
    node_property(Node, bind(_:Port)),
    emit('PORT ~w', [Port]),
    read_term(user_input, _, []),       % until stdin closes
    node_stop(Node).
main([peer, Token0, Target0, Floats0, Pause0, Budget0, Fresh]) :-
    maplist(atom_number, [Token0, Target0, Floats0, Pause0, Budget0],
            [Token, Target, Floats, PauseMs, Budget]),
    must_be(boolean, Fresh),
    node_start('127.0.0.1':0, Node, [token(Token), reply_timeout(10), connect_timeout(5)]),
    node_property(Node, bind(_:Port)),
    emit('PORT ~w', [Port]),
    findall(F, ( between(1, Floats, I), F is I * 0.001 + 0.5 ), Data),
    get_time(Now),
    End is Now + Budget,
    Pause is PauseMs / 1000,
    assertz(data(guid, Data)),
    assertz(plan(guid, plan(Port, Target, Pause, End, Fresh))),
    create_mobile_agent(hostile_bencher, ('127.0.0.1', Port), hostile_hop, [Token]),
    add_payload(hostile_bencher, [(data,2), (plan,2), (departed,3)]),
    execute_agent(hostile_bencher, ('127.0.0.1', Port), hostile_hop),
    read_term(user_input, _, []),
    node_stop(Node).

%!  emit(+Format, +Args) is det.
%
%   One event line on standard output, flushed (called by the agent on
%   either node, as user:emit/2).
emit(Format, Args) :-
    format(user_output, Format, Args),
    nl(user_output),
    flush_output(user_output).

%!  before_move(+Fresh, +Peer, +To) is det.
%
%   Drop the pooled connections before a move to the target when Fresh.
before_move(true, Peer, To) :-
    To =\= Peer,
    !,
    transport_drop_pool.
before_move(_, _, _).

%   The agent: log the arrival, then (until the budget is spent) pause and
%   move on; a move that fails is logged and tried again after the pause.
hostile_hop(guid, (_, Here), main) :-
    get_time(Now),
    (   retract(departed(guid, T0, From))
    ->  user:emit('HOP ~6f ~6f ~w ~w', [T0, Now, From, Here])
    ;   true
    ),
    plan(guid, plan(Peer, Target, Pause, End, Fresh)),
    (   Here =:= Peer -> Next = Target ; Next = Peer ),
    between(1, 1000000, _),
    get_time(T),
    (   T > End, Here =:= Peer
    ->  user:emit('DONE ~6f', [T])
    ;   sleep(Pause),
        user:before_move(Fresh, Peer, Next),
        get_time(T1),
        assertz(departed(guid, T1, Here)),
        user:emit('DEPART ~6f ~w ~w', [T1, Here, Next]),
        catch(move_agent(guid, ('127.0.0.1', Next)), E, true),
        (   var(E)
        ->  true
        ;   retractall(departed(guid, _, _)),
            get_time(T2),
            format(string(Why), '~q', [E]),
            split_string(Why, "\n", " ", Parts),
            atomic_list_concat(Parts, ' ', Flat),
            user:emit('FAIL ~6f ~6f ~w ~w ~w', [T1, T2, Here, Next, Flat]),
            fail
        )
    ),
    !.
