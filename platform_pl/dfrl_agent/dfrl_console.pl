:- module(dfrl_console,
          [ dfrl_console_serve/1,       % +Node
            dfrl_launch_plan/4,         % +Dict, -Name, -Plan, -Options
            dfrl_launch/3,              % +Node, +Dict, -Result
            dfrl_command/2              % +Dict, -Command
          ]).
:- use_module('../tartarus').
:- use_module(dfrl_agent, [dfrl_create/4]).
:- use_module(dfrl_console_events,          % and the events dfrl_log/3,
              [ accept_log/1, emit/1, error_text/2, request_ref/1, % dfrl_driver/3
                key/3, text_atom/2, text_string/2, address/2 ]).
:- use_module('../transport', [transport_request/4]).
:- use_module('../secrets', [take_env_tokens/1, read_token_file/2,
                              token_text_term/2]).
:- use_module(library(http/json),
              [atom_json_dict/3, json_write_dict/3]).
:- use_module(library(main), [main/0, argv_options/3]).
:- autoload(library(error), [must_be/2, domain_error/2, type_error/2]).
:- autoload(library(readutil), [read_line_to_string/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(lists), [append/2, append/3, member/2, memberchk/2,
                             list_to_set/2]).

/** <module> The console node of an experiment, driven in JSON lines

A long-lived platform node that an experiment driver (a Python process)
starts once and talks to over stdin and stdout, one JSON object per line:

    DFRL_TOKEN=T swipl -q platform_pl/dfrl_agent/dfrl_console.pl
            [--host H] [--port P] [--token-file FILE]... [--token T]...
            [--tls DIR]

--host is the address to bind (default 127.0.0.1), --port the port (0,
the default, lets the OS choose). The node's tokens come from the
environment variable DFRL_TOKEN (deleted once read, so that no process
the node starts inherits it) and from --token-file FILE (repeatable),
both one token per line (secrets:take_env_tokens/1; digit-only tokens
are integers, as Tartarus tokens are); --token T still works, with a
warning, as it shows T to every user of the host (ps); the experiment
driver never uses it. --tls the
folder of a node certificate (ca.crt, node.crt, node.key; `dfrl certs
node`): the node then speaks mutual TLS on every connection, in and out
(node_start/3 option tls(Dir)). The node prints

    {"event":"ready","host":H,"port":P}

and then serves requests, one at a time in the order they arrive. Every
request carries an `id` and gets one reply, `{"id":N,"ok":true,...}` or
`{"id":N,"ok":false,"error":"<printable text>"}` (and, for an
error(Formal, _) term, `"formal":{"name":N,"args":[...]}`, its formal as
data); an error inside a request never stops the node. Requests:

  - `{"id":1,"op":"launch","plan":Plan}`: create the dFRL agent of the
    launch plan (dfrl_launch_plan/4) on this node and move it to its
    first stop. Replies `{"agent":Name,"host":H,"port":P}` once it left.
  - `{"id":2,"op":"control","agent":A,"host":H,"port":P,"command":C}`:
    post the control command C (dfrl_command/2) for agent A to the node
    H:P (the agent's first stop) as the platform event dfrl_control/4,
    Args `[A, Command]`, Link this node's own (Host, Port).
  - `{"id":3,"op":"load_program","program":File,"nodes":[[H,P],...]}`:
    load the program file into each node (load_program_at/3 with this
    node's tokens), in order; the first failure is the reply.
  - `{"id":7,"op":"agents","node":[H,P]}`: the agents on the node H:P,
    `{"agents":[{"name":N,"handler":H,"kind":K,"status":S},...]}`.
  - `{"id":4,"op":"join","to":[H,P],"request":R,"robot":Spec,
    "iterations":N}`: ask the driver whose console is H:P to add a robot
    (Spec is passed on untouched; N may be null).
  - `{"id":5,"op":"reply","to":[H,P],"request":R,"result":Result}`:
    answer the join request R that came from the console H:P.
  - `{"id":9,"op":"program","to":[H,P],"name":N,"text":T}`: tell the
    driver whose console is H:P that the program T (file name N) was
    injected, so that it loads it into robots that join later.
  - `{"id":8,"op":"robot","node":[H,P],"request":R}`: send the request
    dfrl_robot(Term) to the robot service (`dfrl robot`) at H:P with
    this node's tokens (transport_request/4) and reply
    `{"result":Answer}`. R and its Term (robot_request/2) and Answer:
      "status"             status       the service's status object
      "start" / "stop"     start / stop true
      "files"              files        [{"name":N,"size":S},...]
      {"configure":Text}   configure(Text)  true (Text: a JSON object
                                        as a string, passed untouched)
      {"fetch":{"name":N,"offset":O,"max":M}}
                           fetch(N, O, M)   {"data":Base64,"eof":Bool}
    An optional "wait_s" bounds the wait for the answer (default
    30 s). Robot requests are served each in a thread of their own, so a
    slow or unreachable robot does not hold up other requests: their
    replies may come out of order (match them by id).
  - `{"id":6,"op":"quit"}` (or end of input): stop the node and exit 0.

Joins travel through the platform: a peer console posts the platform
event dfrl_driver/3 here, printed as event lines for the driver, and
agents post their round-log lines as dfrl_log/3; both are
dfrl_console_events.pl's, where the event lines are listed.
Lines on stdout are written under one mutex, whole, and flushed.
*/

:- initialization(main, main).

opt_type(host,  host,  atom).
opt_type(port,  port,  between(0, 65535)).
opt_type(token, token, atom).
opt_type(token_file, token_file, file).
opt_type(tls,   tls,   atom).

opt_help(host,  "Address to bind (default 127.0.0.1)").
opt_help(port,  "Port to bind (default 0: chosen by the OS)").
opt_help(token, "A token of this node (repeat for several); visible to \c
                 other users (ps): prefer --token-file or DFRL_TOKEN").
opt_help(token_file, "File of this node's tokens, one per line (mode 600)").
opt_help(tls,   "Folder of the node's TLS files (ca.crt, node.crt, node.key): \c
                 mutual TLS on every connection (default: plaintext)").
opt_help(help(usage), " [--host H] [--port P] [--token-file FILE]... \c
                       [--token T]... [--tls DIR]").

main(Argv) :-
    catch(console(Argv), E, ( print_message(error, E), halt(1) )).

console(Argv) :-
    take_env_tokens(EnvTokens),         % first: no child inherits DFRL_TOKEN
    argv_options(Argv, _Positional, Options),
    option(host(Host), Options, '127.0.0.1'),
    option(port(Port), Options, 0),
    findall(T, ( member(token(A), Options), token_term(A, T) ), ArgTokens),
    (   ArgTokens == []
    ->  true
    ;   print_message(warning, dfrl(token_on_command_line))
    ),
    findall(Ts, ( member(token_file(F), Options), read_token_file(F, Ts) ), FileTokens),
    append([ArgTokens|FileTokens], Tokens0),
    append(Tokens0, EnvTokens, Tokens1),
    list_to_set(Tokens1, Tokens),
    set_stream(user_input, encoding(utf8)),
    set_stream(user_output, encoding(utf8)),
    (   Tokens == [] -> TokOpts = [] ; TokOpts = [tokens(Tokens)] ),
    (   option(tls(Dir), Options) -> TlsOpts = [tls(Dir)] ; TlsOpts = [] ),
    append(TokOpts, TlsOpts, NodeOpts),
    node_start(Host:Port, Node, [default(true)|NodeOpts]),
    node_property(Node, address(H:P)),
    emit(_{event:ready, host:H, port:P}),
    call_cleanup(dfrl_console_serve(Node), node_stop(Node)).

%!  dfrl_console_serve(+Node) is det.
%
%   Serve JSON-line requests from user_input on behalf of Node until end
%   of input or a `quit` request. Replies go to user_output.

dfrl_console_serve(Node) :-
    read_line_to_string(user_input, Line),
    (   Line == end_of_file
    ->  true
    ;   serve_line(Node, Line, Continue),
        (   Continue == true
        ->  dfrl_console_serve(Node)
        ;   true
        )
    ).

serve_line(_, Line, true) :-
    split_string(Line, "", " \t\r", [""]),
    !.
serve_line(Node, Line, Continue) :-
    catch(atom_json_dict(Line, Request, []), E, true),
    (   nonvar(E)
    ->  reply(null, error(E)),
        Continue = true
    ;   is_dict(Request)
    ->  request_id(Request, Id),
        serve_request(Node, Id, Request, Continue)
    ;   reply(null, error(error(type_error(json_object, Line), _))),
        Continue = true
    ).

request_id(Request, Id) :-
    (   get_dict(id, Request, Id) -> true ; Id = null ).

serve_request(_, Id, Request, false) :-
    get_dict(op, Request, "quit"),
    !,
    reply(Id, ok(_{})).
serve_request(Node, Id, Request, true) :-
    get_dict(op, Request, "robot"),
    !,
    thread_create(answer(Node, Id, Request), _, [detached(true)]).
serve_request(Node, Id, Request, true) :-
    answer(Node, Id, Request).

answer(Node, Id, Request) :-
    (   catch(request(Node, Request, Result), E, true)
    ->  (   var(E)
        ->  reply(Id, ok(Result))
        ;   reply(Id, error(E))
        )
    ;   reply(Id, error(failed(Request)))
    ).

%   request(+Node, +Request, -Result) is semidet: one console operation.

request(Node, Request, Result) :-
    (   get_dict(op, Request, Op0)
    ->  text_atom(Op0, Op)
    ;   throw(error(existence_error(key, op, Request), _))
    ),
    op(Op, Node, Request, Result).

op(launch, Node, Request, Result) :-
    !,
    key(plan, Request, Plan),
    dfrl_launch(Node, Plan, Result).
op(control, Node, Request, _{agent:Agent, command:Text}) :-
    !,
    key(agent, Request, Agent0), text_atom(Agent0, Agent),
    key(host, Request, Host0), text_atom(Host0, Host),
    key(port, Request, Port), must_be(integer, Port),
    key(command, Request, C),
    dfrl_command(C, Command),
    node_property(Node, link(Link)),
    agent_post(Host:Port, platform, dfrl_control, Link, [Agent, Command]),
    format(string(Text), '~q', [Command]).
op(load_program, _Node, Request, _{program:Program, loaded:Nodes}) :-
    !,
    key(program, Request, Program0), text_atom(Program0, Program),
    key(nodes, Request, Nodes), must_be(list, Nodes),
    forall(member(N, Nodes),
           ( address(N, Address),
             load_program_at(Address, Program, []) )).
op(agents, _Node, Request, _{agents:Agents}) :-
    !,
    key(node, Request, N), address(N, Address),
    remote_agents(Address, Agents0, []),
    maplist(agent_dict, Agents0, Agents).
op(join, Node, Request, _{posted:true}) :-
    !,
    key(to, Request, To), address(To, Address),
    key(request, Request, R), request_ref(R),
    key(robot, Request, Spec), must_be(dict, Spec),
    (   get_dict(iterations, Request, It) -> true ; It = null ),
    (   It == null -> true ; must_be(nonneg, It) ),
    atom_json_dict(SpecText, Spec, [as(string), width(0)]),
    node_property(Node, link(Link)),
    agent_post(Address, platform, dfrl_driver, Link, [join(R, SpecText, It)]).
op(reply, Node, Request, _{posted:true}) :-
    !,
    key(to, Request, To), address(To, Address),
    key(request, Request, R), request_ref(R),
    key(result, Request, Result), must_be(dict, Result),
    atom_json_dict(ResultText, Result, [as(string), width(0)]),
    node_property(Node, link(Link)),
    agent_post(Address, platform, dfrl_driver, Link, [reply(R, ResultText)]).
op(program, Node, Request, _{posted:true}) :-
    !,
    key(to, Request, To), address(To, Address),
    key(name, Request, Name), must_be(string, Name),
    key(text, Request, Text), must_be(string, Text),
    node_property(Node, link(Link)),
    agent_post(Address, platform, dfrl_driver, Link, [program(Name, Text)]).
op(robot, Node, Request, _{result:Result}) :-
    !,
    key(node, Request, N), address(N, Address),
    key(request, Request, R),
    robot_request(R, Term),
    (   node_property(Node, tokens(Tokens)) -> true ; Tokens = [] ),
    dict_default(Request, wait_s, 30, Timeout), must_be(number, Timeout),
    (   Timeout > 0 -> true ; domain_error(positive_timeout, Timeout) ),
    transport_request(Address, dfrl_robot(Term), Answer,
                      [tokens(Tokens), reply_timeout(Timeout)]),
    robot_answer(Term, Answer, Result).
op(Op, _, _, _) :-
    domain_error(console_op, Op).

%   robot_request(+JSON, -Term): a robot request of the `robot` op as the
%   term the robot service answers (contract K5); nothing else passes.

robot_request(R, Term) :-
    string(R),
    atom_string(A, R),
    memberchk(A, [status, start, stop, files]),
    !,
    Term = A.
robot_request(D, configure(Text)) :-
    is_dict(D),
    get_dict(configure, D, Text),
    !,
    must_be(string, Text).
robot_request(D, fetch(Name, Offset, Max)) :-
    is_dict(D),
    get_dict(fetch, D, F),
    !,
    must_be(dict, F),
    key(name, F, Name0), text_atom(Name0, Name),
    key(offset, F, Offset), must_be(nonneg, Offset),
    key(max, F, Max), must_be(positive_integer, Max).
robot_request(R, _) :-
    domain_error(robot_request, R).

%   robot_answer(+Term, +Answer, -JSON)

robot_answer(files, Files, JSON) :-
    !,
    must_be(list, Files),
    maplist(file_json, Files, JSON).
robot_answer(fetch(_, _, _), chunk(Data0, Eof), _{data:Data, eof:Eof}) :-
    !,
    text_string(Data0, Data),
    must_be(boolean, Eof).
robot_answer(status, Dict, Dict) :-
    !,
    must_be(dict, Dict).
robot_answer(_, Answer, Answer).

file_json(file(Name0, Size), _{name:Name, size:Size}) :-
    !,
    text_string(Name0, Name),
    must_be(nonneg, Size).
file_json(F, _) :-
    type_error(robot_file, F).

agent_dict(agent(Name, Handler, Kind, Status),
           _{name:Name, handler:H, kind:Kind, status:S}) :-
    format(string(H), '~q', [Handler]),
    format(string(S), '~q', [Status]).

		 /*******************************
		 *        LAUNCH AND CONTROL	*
		 *******************************/

%!  dfrl_launch_plan(+Dict, -Name, -Plan, -Options) is det.
%
%   Translate a launch plan (JSON object as a dict, strings as strings
%   or atoms) into the arguments of dfrl_create/4:
%
%     { "name": "fed_q",                            agent name (dfrl)
%       "itinerary": [{"host": H, "port": P, "robot": R}, ...],
%       "method": "average",                        (average)
%       "carries": "params",                        tables (default) or params:
%                                                   what the agent aggregates
%       "rounds": 16,                               round budget (1)
%       "rest_s": 0.0,                              rest at the first stop
%       "rounds_log": "/abs/rounds.log",            the agent's JSON-lines log
%       "log_to": [H, P],                           post its lines to this console,
%                                                   which appends them to rounds_log
%       "token": 1111,                              optional: the agent's token
%                                                   (default: this node's tokens)
%       "timeout_s": 3600,                          table read/write limit
%       "skip_after_s": 4,                          the most one move to a stop
%                                                   may take before it is skipped
%       "itinerary_kind": "tree", "fanout": 2 }     chain (default) or tree: clones
%                                                   over a tree of fan-out 2 (default)
%
%   Plan is plan(Stops, Rounds, Rest, Log, Timeout) with Stops a list of
%   stop(Host, Port, Robot); Options are method(M), carries(C),
%   tokens(List), skip_after(S) and itinerary(chain) or itinerary(tree(K)).
%
%   @error domain_error(itinerary, Kind) for another itinerary_kind,
%   domain_error(fanout, K) for a fanout that is not an integer >= 2.

dfrl_launch_plan(D, Name, plan(Stops, Rounds, Rest, Log, Timeout),
                 [method(Method), carries(Carried), tokens(Tokens),
                  skip_after(SkipAfter), itinerary(Kind)]) :-
    must_be(dict, D),
    key(itinerary, D, Stops0),
    must_be(list, Stops0),
    maplist(stop_term, Stops0, Stops),
    dict_default(D, rounds, 1, Rounds),
    dict_default(D, rest_s, 0.0, Rest0), must_be(number, Rest0), Rest is float(Rest0),
    dict_default(D, rounds_log, 'rounds.log', Log0), text_atom(Log0, File),
    (   get_dict(log_to, D, [LH0, LP]), LH0 \== null
    ->  text_atom(LH0, LH), must_be(integer, LP),
        Log = console(LH, LP, File)
    ;   Log = File
    ),
    dict_default(D, timeout_s, 3600, Timeout),
    dict_default(D, skip_after_s, 4, SkipAfter),
    (   number(SkipAfter), SkipAfter > 0
    ->  true
    ;   domain_error(positive_number, skip_after_s(SkipAfter))
    ),
    dict_default(D, method, average, Method0), text_atom(Method0, Method),
    dict_default(D, carries, tables, Carried0), text_atom(Carried0, Carried),
    dict_default(D, name, dfrl, Name0), text_atom(Name0, Name),
    dict_default(D, itinerary_kind, chain, Kind0), text_atom(Kind0, KindName),
    (   KindName == chain
    ->  Kind = chain
    ;   KindName == tree
    ->  dict_default(D, fanout, 2, K),
        (   integer(K), K >= 2 -> true ; domain_error(fanout, K) ),
        Kind = tree(K)
    ;   domain_error(itinerary, KindName)
    ),
    (   get_dict(token, D, Token0), Token0 \== null
    ->  token_term(Token0, Token), Tokens = [Token]
    ;   Tokens = []
    ).

stop_term(D, stop(H, P, R)) :-
    must_be(dict, D),
    key(host, D, H0), text_atom(H0, H),
    key(port, D, P), must_be(integer, P),
    key(robot, D, R0), text_atom(R0, R).

%   A digit-only token is an integer, as Tartarus tokens are.
token_term(T, T) :- number(T), !.
token_term(T, Token) :- text_atom(T, A), token_text_term(A, Token).

dict_default(D, K, Default, V) :-
    (   get_dict(K, D, V0), V0 \== null -> V = V0 ; V = Default ).

%!  dfrl_launch(+Node, +Dict, -Result) is det.
%
%   Create the agent of launch plan Dict on Node and move it to its first
%   stop. Result is the dict `_{agent:Name, host:H, port:P}`. If that move
%   fails, the agent is started with the event `launch` instead: it goes
%   to the first stop it can reach, and Result gets `first_stop_failed`
%   (the error's text); an agent that can reach none logs `aborted`.

dfrl_launch(Node, Dict, Result) :-
    dfrl_launch_plan(Dict, Name, Plan, Options),
    arg(4, Plan, Log),
    (   Log = console(_, _, File) -> accept_log(File) ; true ),
    dfrl_create(Node, Name, Plan, Options),
    Plan = plan([stop(H, P, _)|_], _, _, _, _),
    catch(with_node(Node, move_agent(Name, (H, P))), E, true),
    (   var(E)
    ->  Result = _{agent:Name, host:H, port:P}
    ;   E \= error(transport_error(_, _), _)
    ->  % refused (e.g. tokens, a name in use): not a launch to retry elsewhere
        catch(with_node(Node, purge_agent(Name)), E2, print_message(warning, E2)),
        throw(E)
    ;   % the first stop cannot be reached: the agent's `launch` event goes to the first
        % stop it can reach (with its retries), and logs `aborted` if there is none
        error_text(E, Why),
        node_property(Node, link(Link)),
        agents:agent_execute(Node, Name, Link, launch),
        Result = _{agent:Name, host:H, port:P, first_stop_failed:Why}
    ).

%!  dfrl_command(+Dict, -Command) is det.
%
%   Translate a control command (JSON object as a dict) into the term of
%   contract C3:
%
%     {"join": {"host": H, "port": P, "robot": R}}  join(stop(H, P, R))
%     {"method": "median"}                          method(median)
%     {"stop": true}                                stop
%
%   @error domain_error(dfrl_command, Dict) for anything else.

dfrl_command(D, Command) :-
    must_be(dict, D),
    (   get_dict(join, D, J)
    ->  stop_term(J, Stop),
        Command = join(Stop)
    ;   get_dict(method, D, M0)
    ->  text_atom(M0, M),
        Command = method(M)
    ;   get_dict(stop, D, true)
    ->  Command = stop
    ;   domain_error(dfrl_command, D)
    ).

		 /*******************************
		 *            OUTPUT		*
		 *******************************/

reply(Id, ok(Result)) :-
    put_dict(_{id:Id, ok:true}, Result, Reply),
    emit(Reply).
reply(Id, error(E)) :-
    error_text(E, Text),
    (   formal_data(E, Formal)
    ->  emit(_{id:Id, ok:false, error:Text, formal:Formal})
    ;   emit(_{id:Id, ok:false, error:Text})
    ).

%   formal_data(+Error, -Dict): the formal term of error(Formal, _) as
%   data for the driver, {"name": N, "args": [A, ...]} (atomic arguments
%   as text, compound ones written with ~q), so it can tell e.g. a
%   refused token (permission_error, platform) without reading the text.
formal_data(error(Formal, _), _{name:Name, args:Args}) :-
    compound(Formal),
    compound_name_arguments(Formal, Name, Args0),
    maplist(arg_text, Args0, Args).

arg_text(A, T) :-
    (   atomic(A) -> atom_string(A, T) ; format(string(T), '~q', [A]) ).


