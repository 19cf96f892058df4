:- module(codeload,
          [ load_program/1,             % +File
            load_program_at/3,          % +Address, +File, +Options
            load_program_text/4,        % +Address, +Id, +Text, +Options
            program_module/2            % +Id, -Module
          ]).
:- use_module(node, [current_node/1, node_property/2, ctx_node/2,
                     ctx_authenticated/1, node_option/3]).
:- use_module(platform_errors, [message_text/2]).
:- use_module(code_safety, [check_program_text/2, code_trusted/1, forget_checked_code/0]).
:- use_module(agent_bounds, [bounds_call/4, bounds_warning/2]).
:- use_module(worker_pool, [pool_run/3, pool_retire/0]).
:- use_module(transport).
:- autoload(library(error), [must_be/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(readutil), [read_file_to_string/3]).
:- autoload(library(time), [call_with_time_limit/2]).
:- autoload(library(lists), [append/3, member/2]).

/** <module> Loading agent programs into running nodes

A node can load a program (handlers, helper predicates, aggregation
methods) while it runs: from a local file, or sent by a peer that proves
one of the node's tokens. Errors and warnings raised while loading are
collected and returned to the sender.

Where a program goes:

  - A program loaded locally (load_program/1, consult/1, Tartarus'
    assert_file_to_tartarus/1) is trusted and loads into `user`, where
    new agents find their handlers and agents' modules (which inherit
    from `user`) its helper predicates.
  - A program sent by a peer (load_program_at/3, load_program_text/4)
    loads as source dfrl_program://Id into a module of its own,
    program_module(Id, M), M = 'dfrl_program://Id', which inherits from
    `user`: its bodies see the node's predicates, but its names are its
    own, so two peers' programs never clash, and neither can claim a
    name in `user` for the other or for the node. Loading Id again
    replaces that program (its module and its hook clauses). Other code
    reaches its predicates qualified (M:Goal) or through the mobile hooks
    it adds clauses to (the dFRL aggregation hooks,
    code_safety:mobile_hook/1), whose bodies run in M.

A program sent by a peer is checked as a whole before any of it is
loaded (code_safety:check_program_text/2: every clause and directive;
no hook the Prolog system or a library calls by name), unless the peer
is trusted by name (node option trusted_peers(Names)); a refused program
loads nothing and the sender gets the error. Its initialization goals
(initialization/1 and initialization(G, now), checked as bodies unless
the peer is trusted) do not run while it loads: after the load they run in order, each in M under
the agent bounds of the node (agent_bounds:bounds_call/4: CPU time,
stacks, the size of M, output lines, a slot of max_running_agents) and a
wall-clock limit of 5 times the node's agent_cpu_limit (10 s by default,
60 s if it is infinite; a goal that sleeps takes no CPU). A goal
stopped by a bound unloads the program (its module and hook clauses) and
the sender gets resource_error(program_initialization(Id, Kind)).
*/

:- multifile node:platform_request/4.
:- multifile user:message_hook/3.
:- dynamic user:message_hook/3.

:- thread_local
    collecting/0,
    collected/1,
    deferring/1,                        % SourceId: its initialization goals wait
    deferred/1.                         % Goal, in the order of the text
:- multifile system:term_expansion/2.
:- dynamic system:term_expansion/2.

%!  load_program(+File) is det.
%
%   Load File into `user` on this process (and so into every node it
%   runs). Loading again replaces the file's previous definitions.

load_program(File) :-
    must_be(atomic, File),
    load_files(user:File, [if(true)]),
    forget_checked_code.

%!  load_program_at(+Address, +File, +Options) is det.
%
%   Send the text of File to the platform at Address, which loads it
%   without a restart into a module of its own, program_module(Id, M)
%   with Id the base name of File (see the module doc). Options:
%   tokens(List), the tokens to prove (default the current node's), and
%   the timeouts of transport_open/3.
%
%   @error permission_error(load, platform, Address) if no token fits.
%   @error permission_error(install, code, Culprit) if the sandbox there
%   refused the program (nothing of it was loaded).
%   @error load_errors(Messages) if the program had errors there.
%   @error resource_error(program_initialization(Id, Kind)) if an
%   initialization goal of the program went over a bound there (Kind as
%   agent_bounds.pl's, wall_time(Sec), or running_agents if no slot
%   was free in time); the program was unloaded.

load_program_at(Address, File, Options) :-
    read_file_to_string(File, Text, []),
    file_base_name(File, Base),
    load_program_text(Address, Base, Text, Options).

%!  load_program_text(+Address, +Id, +Text, +Options) is det.
%
%   Like load_program_at/3 for program Text, known there as Id.

load_program_text(Address0, Id, Text, Options) :-
    must_be(atomic, Id),
    must_be(string, Text),
    address_normalize(Address0, Address),
    tokens(Options, Tokens),
    transport_request(Address, load_code(Id, Text), _,
                      [tokens(Tokens), action(load)|Options]).

tokens(Options, Tokens) :-
    (   option(tokens(Tokens), Options)
    ->  true
    ;   catch(current_node(Node), _, fail),
        node_property(Node, tokens(Tokens))
    ->  true
    ;   Tokens = []
    ).

%!  program_module(+Id, -Module) is det.
%
%   Module is where the program a peer sent as Id is loaded:
%   'dfrl_program://Id'. It inherits from `user`.

program_module(Id, Module) :-
    must_be(atomic, Id),
    format(atom(Module), 'dfrl_program://~w', [Id]).

%   load_text(+Node, +Id, +Text): load Text as source dfrl_program://Id
%   into its module. Its initialization goals are held back while it
%   loads (the expansion below) and run afterwards under the bounds,
%   also for a trusted peer (bounds are about resources, not trust: its
%   agents run bounded too).
load_text(Node, Id, Text) :-
    program_module(Id, M),
    SourceId = M,                       % the module is named as the source
    setup_call_cleanup(
        ( open_string(Text, In),
          assertz(collecting),
          assertz(deferring(SourceId))
        ),
        load_files(M:SourceId, [stream(In), if(true)]),
        ( close(In),
          retractall(collecting),
          retractall(deferring(_))
        )),
    forget_checked_code,
    findall(G, retract(deferred(G)), Inits),
    findall(E, retract(collected(E)), Errors),
    (   Errors == []
    ->  true
    ;   throw(error(load_errors(Errors), _))
    ),
    run_inits(Inits, Node, Id, M).

%   The initialization goals of a program, in order, each a
%   bounded call in its module, run as an agent's handler is: in a worker
%   of the `agents` pool (agent_bounds.pl stops it by signalling that
%   thread, which then retires with whatever the stop left in it), while
%   this connection's worker waits for the outcome. A goal that fails is
%   reported as SWI-Prolog reports a failed initialization goal (a
%   warning); an exception is a load error; a bound unloads the program.
run_inits([], _, _, _).
run_inits([G|Gs], Node, Id, M) :-
    init_wall_limit(Node, Wall),
    init_outcome(Node, Id, M, G, Wall, Outcome),
    (   Outcome == true
    ->  true
    ;   Outcome == false
    ->  print_message(warning, init_goal_failed(failed, @(M:G, M:0)))
    ;   Outcome = ball(Ball),
        init_stopped(Ball, Node, Wall, Id, M)
    ),
    run_inits(Gs, Node, Id, M).

%   The job always answers (it catches everything); the wait is bounded
%   all the same, by the wall clock plus the monitor's ten signals.
init_outcome(Node, Id, M, G, Wall, Outcome) :-
    Timeout is Wall + 30,
    setup_call_cleanup(
        message_queue_create(Queue),
        (   pool_run(agents, codeload:init_job(Queue, Node, Id, M, G, Wall), []),
            (   thread_get_message(Queue, outcome(Outcome0), [timeout(Timeout)])
            ->  Outcome = Outcome0
            ;   Outcome = ball(time_limit_exceeded)
            )
        ),
        message_queue_destroy(Queue)).

init_job(Queue, Node, Id, M, G, Wall) :-
    catch(( bounds_call(Node, program(Id), M, codeload:init_call(Wall, M:G))
          ->  Outcome = true
          ;   Outcome = false
          ),
          Ball, Outcome = ball(Ball)),
    (   Outcome = ball(B),
        stop_kind(B, Wall, _)
    ->  pool_retire                     % the stop may have left state in this thread
    ;   true
    ),
    catch(thread_send_message(Queue, outcome(Outcome)), _, true).

%   The wall-clock limit of an initialization goal: 5 x agent_cpu_limit,
%   60 s if that is infinite (the goal holds a connection worker and the
%   sender's reply, whatever the node allows its agents).
init_wall_limit(Node, Wall) :-
    node_option(Node, agent_cpu_limit, CPU),
    (   CPU == infinite
    ->  Wall = 60
    ;   Wall is 5 * CPU
    ).

init_call(Wall, Goal) :-
    call_with_time_limit(Wall, Goal).

init_stopped(Ball, Node, Wall, Id, M) :-
    stop_kind(Ball, Wall, Kind),
    !,
    unload_program(M),
    Error = error(resource_error(program_initialization(Id, Kind)), _),
    bounds_warning(Node, Error),                % rate-limited per node
    throw(Error).
init_stopped(error(Formal, _), _, _, _, _) :-
    !,
    message_text(error(Formal, _), Text),
    throw(error(load_errors([Text]), _)).
init_stopped(Ball, _, _, _, _) :-
    throw(Ball).

stop_kind('$dfrl_bound'(Kind), _, Kind).
stop_kind(time_limit_exceeded, Wall, wall_time(Wall)).
stop_kind(time_limit_exceeded(_), Wall, wall_time(Wall)).
stop_kind(error(resource_error(running_agents), _), _, running_agents).   % no slot in time

%   Take a program out again: the predicates of its module and its
%   clauses of the mobile hooks.
unload_program(M) :-
    forall(( code_safety:mobile_hook(HM:F/A),
             functor(H, F, A),
             catch(clause(HM:H, _, Ref), _, fail),
             clause_property(Ref, source(M)) ),
           erase(Ref)),
    forall(( current_predicate(M:F/A),
             functor(H, F, A),
             \+ predicate_property(M:H, imported_from(_)) ),
           catch(abolish(M:F/A), _, true)).

%   While a program sent by a peer loads, its initialization goals are noted
%   instead of run: a directive is split into its parts, and the
%   initialization/1 and initialization(G, now) parts are kept back.
%   (A program's own expansion hooks are refused; this runs last, after
%   the node's.)
system:term_expansion(Directive, Terms) :-
    deferring(SourceId),
    nonvar(Directive),
    (   Directive = (:- D) -> true ; Directive = (?- D) ),
    prolog_load_context(source, SourceId),
    init_parts(D, Inits, Rest),
    Inits \== [],
    forall(member(G, Inits), assertz(deferred(G))),
    findall((:- R), member(R, Rest), Terms).

init_parts(D, Inits, Rest) :-
    (   var(D)
    ->  Inits = [], Rest = [D]
    ;   D = (A, B)
    ->  init_parts(A, IA, RA),
        init_parts(B, IB, RB),
        append(IA, IB, Inits),
        append(RA, RB, Rest)
    ;   D = initialization(G)
    ->  Inits = [G], Rest = []
    ;   D = initialization(G, now)
    ->  Inits = [G], Rest = []
    ;   Inits = [], Rest = [D]
    ).

%   syntax_error_at(+Id, +Text, +What, +Where)
%
%   The sandbox's reader refused Text with syntax_error(What): throw it
%   again as load_errors(["Id:Line:Column: Syntax error: ..."]), the
%   place found by reading Text term by term (a context of a remote
%   error is replaced by the peer's address, so the place travels in the
%   formal, as the messages of other load errors do). If no term of Text
%   fails to read on its own, the error is thrown as it came.

syntax_error_at(Id, Text, What, Where) :-
    (   first_syntax_error(Text, Line, LinePos, What1)
    ->  message_text(error(syntax_error(What1), _), Message),
        format(string(Located), "~w:~d:~d: ~w", [Id, Line, LinePos, Message]),
        throw(error(load_errors([Located]), _))
    ;   throw(error(syntax_error(What), Where))
    ).

first_syntax_error(Text, Line, LinePos, What) :-
    setup_call_cleanup(
        open_string(Text, In),
        catch(( repeat,
                read_term(In, Term, [module(user), syntax_errors(error)]),
                Term == end_of_file,
                !,
                fail
              ),
              error(syntax_error(What), stream(_, Line, LinePos, _)),
              true),
        close(In)).

user:message_hook(Term, error, _Lines) :-
    collecting,
    message_text(Term, Text),
    assertz(collected(Text)),
    fail.

node:platform_request(load_code(Id, Text), Ctx, Reply, true) :-
    ctx_node(Ctx, Node),
    (   ctx_authenticated(Ctx)
    ->  must_be(atomic, Id),
        must_be(string, Text),
        (   code_trusted(Ctx)
        ->  true
        ;   catch(check_program_text(Id, Text), error(syntax_error(What), Where),
                  syntax_error_at(Id, Text, What, Where))
        ),
        load_text(Node, Id, Text),
        Reply = ok(loaded(Id))
    ;   node_property(Node, address(Here)),
        Reply = error(error(permission_error(load, platform, Here), _))
    ).

:- multifile prolog:error_message//1.

prolog:error_message(load_errors(Errors)) -->
    [ 'The program did not load cleanly:'-[] ],
    error_lines(Errors).

error_lines([]) --> [].
error_lines([E|Es]) --> [ nl, '  ~w'-[E] ], error_lines(Es).
