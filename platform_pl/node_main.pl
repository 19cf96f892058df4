/*  Run one platform node as a program:

        DFRL_TOKEN=T swipl platform_pl/node_main.pl [--host H] [--port P]
                                       [--token-file FILE]... [--token T]...
                                       [--advertise HOST[:PORT]] [--store DIR]
                                       [--insecure] [--tls DIR]
                                       [--tls-peer NAME]... [--trust NAME]...
                                       [--consult FILE]... [--interactive]
                                       [BOUND VALUE]...

    Binds H:P (H may be 0.0.0.0: every interface), prints "dfrl node
    listening on A:P" with the address it advertises (--advertise, default
    H, or the host name for 0.0.0.0) once it listens, then serves until
    killed (or, with --interactive, until the toplevel ends). --store DIR
    keeps the node's id (and custody state) in DIR.

    The node's tokens come from the environment variable DFRL_TOKEN, which
    is deleted from the environment once read (so that processes the node
    starts do not inherit it), and from each --token-file FILE (keep it
    mode 600); both hold one token per line (secrets.pl, take_env_tokens/1).
    --token T still works but puts T where every user of the host sees it
    (ps), so it prints a warning. Digit-only tokens are integers, as
    Tartarus tokens are. Off loopback, a node with a token under 128 bits
    of entropy (or none) does not start unless --insecure is given (`dfrl
    secret` prints a strong token); on loopback such a token is accepted
    with a warning, and a node without a token (open: any local user may
    send it agents and code) starts with a warning. --tls DIR (a node's ca.crt,
    node.crt, node.key from `dfrl certs node`) makes every connection
    mutual TLS, and then any token is accepted anywhere; --tls-peer NAME
    (repeatable) lets only peers whose certificate names NAME send agents
    or code; --trust NAME (repeatable, with --tls) installs the code of a
    peer whose certificate names NAME without the sandbox check (node
    option trusted_peers(Names)). A malformed command line is
    reported on stderr and exits with status 2; a node that cannot start
    (address taken, weak token) prints why and exits with status 1.

    Bounds on agents (node options of node_start/3, agent_bounds.pl),
    each taking a value or `infinite`: --agent-cpu-limit SEC,
    --agent-stack-limit BYTES, --agent-module-limit BYTES,
    --agent-post-limit N, --agent-log-limit N, --max-agents N,
    --clone-limit N, --agent-memory-budget BYTES, --max-running-agents N,
    --agent-wall-limit SEC, --agent-idle-limit SEC, --max-agents-per-peer N,
    --max-running-per-peer N, --peer-post-limit N;
    and --agent-slot-wait SEC, --max-frame-size BYTES (values only).

    The arguments are parsed here, not with library(optparse): --token,
    --token-file and --consult may be repeated, and optparse keeps only
    the last occurrence of a flag.
*/
:- use_module(tartarus).
:- use_module(secrets, [take_env_tokens/1, read_token_file/2, token_text_term/2]).
:- use_module(library(main)).

:- initialization(main, main).

main(Argv) :-
    take_env_tokens(EnvTokens),         % first: no child inherits DFRL_TOKEN
    catch(parse_args(Argv, Options), error(usage(Why), _), usage(Why)),
    option_value(host, Options, localhost, Host),
    option_value(port, Options, 0, Port),
    findall(T, member(token(T), Options), ArgTokens),
    (   ArgTokens == []
    ->  true
    ;   print_message(warning, dfrl(token_on_command_line))
    ),
    findall(F, member(token_file(F), Options), TokenFiles),
    catch(maplist(read_token_file, TokenFiles, FileTokens), E0,
          ( print_message(error, E0), halt(1) )),
    append([ArgTokens|FileTokens], Tokens0),
    append(Tokens0, EnvTokens, Tokens1),
    list_to_set(Tokens1, Tokens),
    findall(F, member(consult(F), Options), Files),
    findall(N, member(tls_peer(N), Options), Peers),
    findall(N, member(trust(N), Options), Trusted),
    findall(O, ( ( member(O0, [advertise(_), store(_), tls(_)])
                 ; bound_flag(_, Name, _),
                   O0 =.. [Name, _]
                 ),
                 last_option(Options, O0),
                 O = O0 ),
            Extra),
    (   memberchk(insecure, Options)
    ->  Extra0 = [insecure(true)|Extra]
    ;   Extra0 = Extra
    ),
    (   Peers == []
    ->  Extra1 = Extra0
    ;   Extra1 = [tls_peers(Peers)|Extra0]
    ),
    (   Trusted == []
    ->  Extra2 = Extra1
    ;   Extra2 = [trusted_peers(Trusted)|Extra1]
    ),
    (   Tokens == []
    ->  NodeOptions = [default(true)|Extra2]
    ;   NodeOptions = [tokens(Tokens), default(true)|Extra2]
    ),
    catch(node_start(Host:Port, Node, NodeOptions), E,
          ( start_failed(Host:Port, E), halt(1) )),
    (   node:loopback_host(Host), \+ memberchk(tls(_), Options)
    ->  warn_weak_tokens(Tokens)
    ;   true
    ),
    forall(member(F, Files), load_program(F)),
    node_property(Node, address(H:P)),
    format("dfrl node listening on ~w:~w~n", [H, P]),
    flush_output,
    (   memberchk(interactive, Options)
    ->  prolog
    ;   thread_get_message(_)          % serve until killed
    ).

warn_weak_tokens(Tokens) :-
    forall(( member(T, Tokens),
             node:token_entropy_bits(T, Bits),
             Bits < 128 ),
           format(user_error,
                  "Warning: a token of ~d bits serves on loopback only \c
                   (128 needed elsewhere; `dfrl secret` prints one)~n", [Bits])).

%   start_failed(+Address, +Error): say why the node did not start; a port
%   another process holds is named, with what to do about it.
start_failed(Address, error(socket_error(eaddrinuse, _), _)) :-
    !,
    print_message(error, dfrl(address_in_use(Address))).
start_failed(_, E) :-
    print_message(error, E).

usage(Why) :-
    format(user_error, "~w~n", [Why]),
    format(user_error,
           "usage: swipl node_main.pl [--host H] [--port P] \c
            [--token-file FILE]... [--token T]... \c
            [--advertise HOST[:PORT]] [--store DIR] [--insecure] \c
            [--tls DIR] [--tls-peer NAME]... [--trust NAME]... \c
            [--consult FILE]... [--interactive] \c
            [--agent-cpu-limit SEC] [--agent-stack-limit BYTES] \c
            [--agent-module-limit BYTES] [--agent-post-limit N] \c
            [--agent-log-limit N] [--max-agents N] [--clone-limit N] \c
            [--agent-memory-budget BYTES] [--max-running-agents N] \c
            [--agent-wall-limit SEC] [--agent-idle-limit SEC] \c
            [--max-agents-per-peer N] [--max-running-per-peer N] \c
            [--peer-post-limit N] \c
            [--agent-slot-wait SEC] [--max-frame-size BYTES] \c
            (a bound's value may be infinite)~n", []),
    halt(2).

%   parse_args(+Argv, -Options): Options in command-line order.
parse_args([], []).
parse_args([Flag|Argv0], [Option|Options]) :-
    (   flag_arg(Flag, Name, Type)
    ->  (   Argv0 = [Value0|Argv]
        ->  typed_value(Type, Flag, Value0, Value),
            Option =.. [Name, Value]
        ;   usage_error("~w needs a value", [Flag])
        )
    ;   Flag == '--interactive'
    ->  Option = interactive,
        Argv = Argv0
    ;   Flag == '--insecure'
    ->  Option = insecure,
        Argv = Argv0
    ;   usage_error("Unknown argument: ~w", [Flag])
    ),
    parse_args(Argv, Options).

flag_arg('--host', host, atom).
flag_arg('--port', port, integer).
flag_arg('--token', token, token).
flag_arg('--token-file', token_file, atom).
flag_arg('--consult', consult, atom).
flag_arg('--advertise', advertise, address).
flag_arg('--store', store, atom).
flag_arg('--tls', tls, atom).
flag_arg('--tls-peer', tls_peer, atom).
flag_arg('--trust', trust, atom).
flag_arg(Flag, Name, Type) :-
    bound_flag(Flag, Name, Type).

%   Bounds on agents and frames: flag, node option, type.
bound_flag('--agent-cpu-limit', agent_cpu_limit, limit(number)).
bound_flag('--agent-stack-limit', agent_stack_limit, limit(integer)).
bound_flag('--agent-module-limit', agent_module_limit, limit(integer)).
bound_flag('--agent-post-limit', agent_post_limit, limit(integer)).
bound_flag('--agent-log-limit', agent_log_limit, limit(integer)).
bound_flag('--max-agents', max_agents, limit(integer)).
bound_flag('--clone-limit', clone_limit, limit(integer)).
bound_flag('--agent-memory-budget', agent_memory_budget, limit(integer)).
bound_flag('--max-running-agents', max_running_agents, limit(integer)).
bound_flag('--agent-slot-wait', agent_slot_wait, positive(number)).
bound_flag('--agent-wall-limit', agent_wall_limit, limit(number)).
bound_flag('--agent-idle-limit', agent_idle_limit, limit(number)).
bound_flag('--max-agents-per-peer', max_agents_per_peer, limit(integer)).
bound_flag('--max-running-per-peer', max_running_per_peer, limit(integer)).
bound_flag('--peer-post-limit', peer_post_limit, limit(integer)).
bound_flag('--max-frame-size', max_frame_size, positive(integer)).

typed_value(atom, _, V, V).
typed_value(integer, Flag, V0, V) :-
    (   atom_number(V0, V), integer(V)
    ->  true
    ;   usage_error("~w needs an integer, not ~w", [Flag, V0])
    ).
typed_value(address, Flag, V0, V) :-
    (   sub_atom(V0, B, 1, A, ':'),
        sub_atom(V0, _, A, 0, PortText),
        \+ sub_atom(PortText, _, _, _, ':')
    ->  sub_atom(V0, 0, B, _, Host),
        (   atom_number(PortText, Port), integer(Port), between(1, 65535, Port)
        ->  V = Host:Port
        ;   usage_error("~w needs HOST or HOST:PORT, not ~w", [Flag, V0])
        )
    ;   V = V0
    ),
    (   V == '' ; V = '':_
    ->  usage_error("~w needs a host name", [Flag])
    ;   true
    ).
typed_value(token, _, V0, V) :-
    token_text_term(V0, V).
typed_value(limit(_), _, infinite, infinite) :-
    !.
typed_value(limit(Type), Flag, V0, V) :-
    (   positive_value(Type, V0, V)
    ->  true
    ;   usage_error("~w needs a positive ~w or infinite, not ~w", [Flag, Type, V0])
    ).
typed_value(positive(Type), Flag, V0, V) :-
    (   positive_value(Type, V0, V)
    ->  true
    ;   usage_error("~w needs a positive ~w, not ~w", [Flag, Type, V0])
    ).

positive_value(Type, V0, V) :-
    catch(atom_number(V0, V), _, fail),
    V > 0,
    (   Type == integer -> integer(V) ; true ).

usage_error(Format, Args) :-
    format(string(Why), Format, Args),
    throw(error(usage(Why), _)).

option_value(Name, Options, Default, Value) :-
    Opt =.. [Name, V],
    (   last_option(Options, Opt)
    ->  Value = V
    ;   Value = Default
    ).

last_option(Options, Opt) :-
    reverse(Options, Rev),
    memberchk(Opt, Rev).
