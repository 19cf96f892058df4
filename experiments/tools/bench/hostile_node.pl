/*  The processes of the hostile benchmark (experiments/tools/bench/hostile.py).

    swipl hostile_node.pl target TOKEN [TLS_DIR TRUSTED]
        A platform node on 127.0.0.1 (OS-chosen port) with the platform's
        default limits: the node under attack. It hosts a static agent
        `victim` whose payload (secret/2) no other agent may read. Prints
        "PORT <p>", then serves and answers commands on standard input,
        until it closes: `probe.` prints a JSON line with the agents it
        hosts, its double_quotes flag in `user`, its max_frame_size,
        max_connections, max_agents, the most workers of its connection
        pool, its dfrl_pool_idle flag and the size and idle workers of
        each of its worker pools (pool/1);
        `purge.` purges every agent but the benchmark's own (the operator
        cleaning up between two attacks) and prints how many. With TLS_DIR
        (a control run only) it serves mutual TLS and trusts the peer
        named TRUSTED (trusted_peers/1): that peer's code is not checked.
        The environment variable DFRL_HOSTILE_POOL_IDLE, if set, is its flag
        dfrl_pool_idle (seconds before an idle pool worker exits).

    swipl hostile_node.pl peer TOKEN TARGET_PORT FLOATS PAUSE_MS BUDGET_S FRESH [TLS_DIR]
        An authenticated peer: a node on 127.0.0.1 and an agent whose payload
        holds FLOATS floats, moved to the target and back, PAUSE_MS between
        two hops, until BUDGET_S seconds have passed. With FRESH = true the
        peer keeps no pooled connection (flag dfrl_pool_max 0), so every move
        to the target opens a new connection and passes the target's
        acceptor and admission; with false, pooled connections are reused.
        Reads commands on standard input until it closes: `relaunch.`
        starts a new agent if none is at the peer (after the target
        stopped it) and prints a JSON line saying whether it did.
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
:- use_module('../../../platform_pl/tartarus').
:- use_module(library(main)).
:- use_module(library(http/json), [json_write_dict/3]).
:- use_module('../../../platform_pl/agents', [agent_list/2, agent_exists/2, agent_purge/2]).
:- use_module('../../../platform_pl/node', [node_option/3]).
:- use_module('../../../platform_pl/worker_pool', [pool_statistics/2]).

:- initialization(main, main).

:- dynamic data/2, departed/3, plan/2, secret/2.

main([target, Token0|Trust]) :-
    set_stream(user_output, buffer(line)),
    atom_number(Token0, Token),
    (   Trust = [Dir, Name]
    ->  Extra = [tls(Dir), trusted_peers([Name])]
    ;   Extra = []
    ),
    (   getenv('DFRL_HOSTILE_POOL_IDLE', Idle0)      % tests: pool workers expire sooner
    ->  atom_number(Idle0, Idle),
        set_prolog_flag(dfrl_pool_idle, Idle)
    ;   true
    ),
    node_start('127.0.0.1':0, Node, [token(Token)|Extra]),
    node_property(Node, bind(_:Port)),
    assertz(secret(guid, 'the victim''s secret')),
    create_static_agent(victim, ('127.0.0.1', Port), victim, [Token]),
    add_payload(victim, [(secret, 2)]),
    emit('PORT ~w', [Port]),
    commands(Node),
    node_stop(Node).
main([peer, Token0, Target0, Floats0, Pause0, Budget0, Fresh|Tls]) :-
    set_stream(user_output, buffer(line)),
    maplist(atom_number, [Token0, Target0, Floats0, Pause0, Budget0],
            [Token, Target, Floats, PauseMs, Budget]),
    must_be(boolean, Fresh),
    (   Fresh == true                   % no connection is kept: each move dials anew
    ->  set_prolog_flag(dfrl_pool_max, 0)
    ;   true
    ),
    (   Tls = [Dir] -> Extra = [tls(Dir)] ; Extra = [] ),
    node_start('127.0.0.1':0, Node,
               [token(Token), reply_timeout(10), connect_timeout(5)|Extra]),
    node_property(Node, bind(_:Port)),
    emit('PORT ~w', [Port]),
    findall(F, ( between(1, Floats, I), F is I * 0.001 + 0.5 ), Data),
    get_time(Now),
    End is Now + Budget,
    Pause is PauseMs / 1000,
    assertz(data(guid, Data)),
    assertz(plan(guid, plan(Port, Target, Pause, End))),
    launch(Token, Port),
    peer_commands(Node, Token, Port),
    node_stop(Node).

%   The bencher agent, created here and started.
launch(Token, Port) :-
    retractall(departed(guid, _, _)),
    create_mobile_agent(hostile_bencher, ('127.0.0.1', Port), hostile_hop, [Token]),
    add_payload(hostile_bencher, [(data,2), (plan,2), (departed,3)]),
    execute_agent(hostile_bencher, ('127.0.0.1', Port), hostile_hop).

%   The peer's commands, until standard input closes: `relaunch.` starts
%   a new bencher agent if none is here (the benchmark sends it after the
%   target stopped the old one) and prints whether it did.
peer_commands(Node, Token, Port) :-
    catch(read_term(user_input, C, []), _, C = end_of_file),
    (   C == end_of_file
    ->  true
    ;   C == relaunch
    ->  (   agent_exists(Node, hostile_bencher)
        ->  Done = false
        ;   launch(Token, Port),
            Done = true
        ),
        json_line(_{event: relaunch, launched: Done}),
        peer_commands(Node, Token, Port)
    ;   print_message(error, format('unknown command ~q', [C])),
        peer_commands(Node, Token, Port)
    ).

%   The target's commands (see the header), until standard input closes.
commands(Node) :-
    catch(read_term(user_input, C, []), _, C = end_of_file),
    (   C == end_of_file
    ->  true
    ;   command(C, Node),
        commands(Node)
    ).

command(probe, Node) :-
    !,
    agent_list(Node, Agents),
    length(Agents, N),
    current_prolog_flag(double_quotes, DQ),
    maplist(node_option(Node), [max_frame_size, max_connections, max_agents],
            [Max, MaxConn, MaxAgents]),
    (   catch(node_acceptor:connection_workers_max(ConnWorkers), _, fail)
    ->  true
    ;   ConnWorkers is max(16, 2 * MaxConn)     % node.pl's formula when this was written
    ),
    current_prolog_flag(dfrl_pool_idle, Idle),
    findall(P-_{size: S, idle: I},
            ( pool(P), pool_statistics(P, pool{size: S, idle: I}) ),
            PoolPairs),
    dict_pairs(Pools, pools, PoolPairs),
    json_line(_{event: probe, agents: N, double_quotes: DQ, max_frame_size: Max,
                max_connections: MaxConn, max_agents: MaxAgents,
                connection_workers_max: ConnWorkers, pool_idle_s: Idle, pools: Pools}).
command(purge, Node) :-
    !,
    findall(A, ( agent_exists(Node, A), A \== victim, A \== hostile_bencher ), As),
    forall(member(A, As), catch(agent_purge(Node, A), _, true)),
    length(As, N),
    json_line(_{event: purged, agents: N}).
command(C, _) :-
    print_message(error, format('unknown command ~q', [C])).

%   The node's worker pools (worker_pool.pl): connections (node.pl; at
%   most connection_workers_max), agents (agents.pl), messages
%   (messages.pl), dfrl_bound_notices (agent_bounds.pl; at most 2).
pool(connections).
pool(agents).
pool(messages).
pool(dfrl_bound_notices).

json_line(Dict) :-
    with_output_to(string(S), json_write_dict(current_output, Dict, [width(0)])),
    emit('~s', [S]).

victim(guid, _, _).

emit(Format, Args) :-
    format(user_output, Format, Args),
    nl(user_output),
    flush_output(user_output).

%   The agent: log the arrival, then (until the budget is spent) pause and
%   move on; a move that fails is logged and tried again after the pause.
%   It catches error(_, _) only: a sandbox may refuse a catcher that could
%   take the platform's stop of an agent.
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
        catch(move_agent(guid, ('127.0.0.1', Next)), error(F, C), true),
        (   var(F)
        ->  true
        ;   retractall(departed(guid, _, _)),
            get_time(T2),
            format(string(Why), '~q', [error(F, C)]),
            split_string(Why, "\n", " ", Parts),
            atomic_list_concat(Parts, ' ', Flat),
            format(user_output, 'FAIL ~6f ~6f ~w ~w ~w~n', [T1, T2, Here, Next, Flat]),
            fail
        )
    ),
    !.
