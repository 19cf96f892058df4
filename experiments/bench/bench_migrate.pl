/*  Migration benchmark agent: run by experiments/bench/migrate.py.

    swipl bench_migrate.pl peer TOKEN [TLS_DIR]
        start a platform on an OS-chosen port, print "PORT <p>", serve until
        standard input closes.
    swipl bench_migrate.pl home TOKEN PEER_PORT FLOATS HOPS [TLS_DIR]
        start a platform, create an agent whose payload is a list of FLOATS
        floats, bounce it HOPS times between home and peer, print one line
        "LATENCIES_MS [..]" (one figure per hop, from the call of move_agent
        at the source to the start of the handler at the destination), then
        serve until standard input closes. (The agent prints the line itself:
        its code runs in the sandbox at the peer, which allows output, not
        messages to other threads.)
    With TLS_DIR (a node's ca.crt, node.crt, node.key), both platforms
    speak mutual TLS (node option tls(Dir)).
*/
:- use_module('../../platform_pl/tartarus').
:- use_module(library(main)).

:- dynamic bench/3, data/2, departed/2, lat/2, plan/2, user:bench_done/1.

:- initialization(main, main).

main(['peer', Token0|Tls]) :-
    atom_number(Token0, Token),
    tls_options(Tls, TlsOptions),
    node_start(localhost:0, Node, [token(Token)|TlsOptions]),
    node_property(Node, address(_:Port)),
    format("PORT ~w~n", [Port]),
    flush_output,
    read_term(user_input, _, []),   % until stdin closes
    node_stop(Node).
main(['home', Token0, Peer0, Floats0, Hops0|Tls]) :-
    maplist(atom_number, [Token0, Peer0, Floats0, Hops0],
            [Token, Peer, Floats, Hops]),
    tls_options(Tls, TlsOptions),
    node_start(localhost:0, Node, [token(Token)|TlsOptions]),
    node_property(Node, address(_:Home)),
    findall(F, ( between(1, Floats, I), F is I * 0.001 + 0.5 ), Data),
    assertz(data(guid, Data)),
    assertz(lat(guid, [])),
    assertz(plan(guid, plan(Home, Peer, Hops))),
    create_mobile_agent(bencher, (localhost, Home), bench, [Token]),
    add_payload(bencher, [(data,2), (lat,2), (plan,2), (departed,2)]),
    execute_agent(bencher, (localhost, Home), bench),
    read_term(user_input, _, []),   % the agent prints its figures; then stdin closes
    node_stop(Node).

tls_options([], []).
tls_options([Dir], [tls(Dir)]).

bench(guid, (_, Port), main) :-
    get_time(Now),
    (   retract(departed(guid, T0))
    ->  Ms is (Now - T0) * 1000,
        retract(lat(guid, L0)),
        assertz(lat(guid, [Ms|L0]))
    ;   true
    ),
    lat(guid, L),
    length(L, Done),
    plan(guid, plan(Home, Peer, Hops)),
    (   Port =:= Home -> Next = Peer ; Next = Home ),
    (   Done >= Hops
    ->  (   Port =:= Home
        ->  reverse(L, InOrder),
            format(user_output, "LATENCIES_MS ~w~n", [InOrder]),
            flush_output
        ;   move_agent(guid, (localhost, Home))
        )
    ;   get_time(T1),
        assertz(departed(guid, T1)),
        move_agent(guid, (localhost, Next))
    ).
