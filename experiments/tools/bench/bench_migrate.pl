/*  Migration benchmark agent: run by experiments/tools/bench/migrate.py.

    swipl bench_migrate.pl peer TOKEN [TLS_DIR]
        start a platform on an OS-chosen port and a naive text server on
        another, print "PORT <p> NAIVE <q>", serve until standard input
        closes.
    swipl bench_migrate.pl naive TOKEN NAIVE_PORT FLOATS HOPS
        the naive hop, for comparison: make the same agent as `home`,
        and HOPS times write its record as text (write_canonical/2 on a
        plain socket stream, TCP_NODELAY) to the naive server, which reads it back
        with read_term/3 and answers `ok.`; print "NAIVE_MS [..]" (one
        figure per hop: from the first byte written to the answer).
    swipl bench_migrate.pl home TOKEN PEER_PORT FLOATS HOPS [TLS_DIR]
        start a platform, print "NATIVE B V D" (whether bulk_write.pl,
        float_vectors.pl and tls.pl's direct write run their foreign code:
        true/false), create an agent whose payload is a list of FLOATS
        floats (FLOATS given as packed:N: the same N floats packed, as
        float_vectors.pl packs the tables the dFRL agent carries), bounce
        it HOPS times between home and peer, printing a line
        "ARRIVAL Ms Port Seconds" for every arrival (the hop's time, from
        the call of move_agent at the source to the start of the handler
        at the destination, `-` for an arrival that ends no timed hop; the
        process's CPU time then; see bench_hop_handler.pl) and at the end
        "ARRIVALS_END", then serve until standard input closes. (The agent
        prints the lines itself: its code runs in the sandbox, which allows
        output, not messages to other threads.)
    With TLS_DIR (a node's ca.crt, node.crt, node.key), both platforms
    speak mutual TLS (node option tls(Dir)).
    With the environment variable DFRL_STEP_TRACE=DIR, each process times
    the steps of every hand-over (step_trace.pl) and writes them to
    DIR/peer.jsonl or DIR/home.jsonl when it ends (migrate.py's
    phase_breakdown/2 reads them). With DFRL_HOP_PROBE=DIR, the platform
    is compiled with its hop probes (platform_pl/hop_probe.pl) and each
    process writes the points it stamped to DIR/peer.probe or
    DIR/home.probe, one "Point Seconds" a line (migrate.py's
    hop_timeline/2 reads them).
*/
:- use_module('../../../platform_pl/tartarus').
:- use_module('../../../platform_pl/secrets', [take_env_tokens/1]).
:- use_module('../../../platform_pl/float_vectors',
              [vector_packed/2, float_vectors_native/1]).
:- use_module('../../../platform_pl/bulk_write', [bulk_write_native/1]).
:- use_module('../../../platform_pl/tls', [tls_direct_native/1]).
:- use_module('../../../platform_pl/hop_probe', [hop_probe_stamps/1]).
:- use_module(library(main)).
:- use_module(library(socket)).
:- use_module(step_trace, [step_trace_start/0, step_trace_write/1]).

:- dynamic bench/3, data/2, departed/2, done/2, unsaid/2, plan/2, user:bench_done/1.

:- initialization(main, main).

env_token(Token) :-
    (   take_env_tokens([Token|_])
    ->  true
    ;   format(user_error, "bench_migrate: DFRL_TOKEN is not set~n", []),
        halt(2)
    ).

%   The token comes in the environment (DFRL_TOKEN), never in argv.
main(['peer'|Tls]) :-
    step_trace_start,
    env_token(Token),
    tls_options(Tls, TlsOptions),
    node_start(localhost:0, Node, [token(Token)|TlsOptions]),
    node_property(Node, address(_:Port)),
    naive_server(NaivePort),
    format("PORT ~w NAIVE ~w~n", [Port, NaivePort]),
    flush_output,
    read_term(user_input, _, []),   % until stdin closes
    step_trace_write(peer),
    probe_write(peer),
    node_stop(Node).
main(['home', Peer0, Floats0, Hops0|Tls]) :-
    step_trace_start,
    env_token(Token),
    maplist(atom_number, [Peer0, Hops0], [Peer, Hops]),
    payload_spec(Floats0, Floats),
    tls_options(Tls, TlsOptions),
    node_start(localhost:0, Node, [token(Token)|TlsOptions]),
    node_property(Node, address(_:Home)),
    bench_agent(Home, Peer, Floats, Hops, Token),
    bulk_write_native(Bulk),
    float_vectors_native(Vectors),
    tls_direct_native(Direct),
    format("NATIVE ~w ~w ~w~n", [Bulk, Vectors, Direct]),
    flush_output,
    execute_agent(bencher, (localhost, Home), bench),
    read_term(user_input, _, []),   % the agent prints its figures; then stdin closes
    step_trace_write(home),
    probe_write(home),
    node_stop(Node).

main(['naive', Naive0, Floats0, Hops0]) :-
    env_token(Token),
    maplist(atom_number, [Naive0, Floats0, Hops0], [NaivePort, Floats, Hops]),
    node_start(localhost:0, Node, [token(Token)]),
    node_property(Node, address(_:Home)),
    bench_agent(Home, Home, Floats, 0, Token),
    agents:agent_export(Node, bencher, Record0),
    setarg(4, Record0, []),                 % as migration.pl sends it
    setup_call_cleanup(
        tcp_connect(localhost:NaivePort, Pair, [nodelay(true)]),
        findall(Ms, ( between(1, Hops, _), naive_hop(Pair, Record0, Ms) ), L),
        close(Pair)),
    format("NAIVE_MS ~w~n", [L]),
    flush_output,
    node_stop(Node).

%   FLOATS: N (a list) or packed:N.
payload_spec(Spec, Floats) :-
    (   atomic_list_concat([packed, N0], :, Spec)
    ->  atom_number(N0, N),
        Floats = packed(N)
    ;   atom_number(Spec, Floats)
    ).

%   The benchmark agent, with a payload of Floats floats (packed(N): N
%   floats packed).
bench_agent(Home, Peer, Floats, Hops, Token) :-
    (   Floats = packed(N)
    ->  float_data(N, List),
        vector_packed(List, Data)
    ;   float_data(Floats, Data)
    ),
    assertz(data(guid, Data)),
    assertz(done(guid, 0)),
    assertz(unsaid(guid, [])),
    assertz(plan(guid, plan(Home, Peer, Hops))),
    create_mobile_agent(bencher, (localhost, Home), bench, [Token]),
    add_payload(bencher, [(data,2), (done,2), (unsaid,2), (plan,2), (departed,2)]).

float_data(N, Floats) :-
    findall(F, ( between(1, N, I), F is I * 0.001 + 0.5 ), Floats).

naive_hop(Pair, Term, Ms) :-
    stream_pair(Pair, In, Out),
    get_time(T0),
    write_canonical(Out, Term),
    write(Out, ' .\n'),
    flush_output(Out),
    read_term(In, ok, []),
    get_time(T1),
    Ms is (T1 - T0) * 1000.

%   The naive server: a thread that reads terms from each connection and
%   answers ok to each.
naive_server(Port) :-
    tcp_socket(S),
    tcp_setopt(S, reuseaddr),
    tcp_bind(S, localhost:Port),
    tcp_listen(S, 5),
    thread_create(naive_accept(S), _, [detached(true)]).

naive_accept(S) :-
    tcp_accept(S, Client, _),
    thread_create(naive_serve(Client), _, [detached(true)]),
    naive_accept(S).

%   TCP_NODELAY on both ends, as the platform's connections: otherwise
%   Nagle's algorithm and delayed acknowledgements add some 40 ms to a
%   hop, which is not what the naive hop is there to measure.
naive_serve(Client) :-
    tcp_setopt(Client, nodelay),
    setup_call_cleanup(
        tcp_open_socket(Client, Pair),
        ( stream_pair(Pair, In, Out), naive_loop(In, Out) ),
        close(Pair, [force(true)])).

naive_loop(In, Out) :-
    read_term(In, T, []),
    (   T == end_of_file
    ->  true
    ;   format(Out, "ok.~n", []),
        flush_output(Out),
        naive_loop(In, Out)
    ).

%   The hop probes' stamps, to DIR/Role.probe (DFRL_HOP_PROBE=DIR).
probe_write(Role) :-
    (   getenv('DFRL_HOP_PROBE', Dir), Dir \== '', Dir \== '0'
    ->  hop_probe_stamps(Stamps),
        format(atom(File), '~w/~w.probe', [Dir, Role]),
        setup_call_cleanup(
            open(File, write, Out),
            forall(member(stamp(P, T), Stamps), format(Out, "~w ~6f~n", [P, T])),
            close(Out))
    ;   true
    ).

tls_options([], []).
tls_options([Dir], [tls(Dir)]).

:- include(bench_hop_handler).
