:- module(code_safety,
          [ check_agent_record/1,       % +Record
            check_program_text/2,       % +Id, +Text
            check_post/3,               % +Node, +Agent, +Goal
            code_trusted/1,             % +Ctx
            forget_checked_code/0,
            peer_trusted/2,             % +Node, +PeerName
            record_seal/3,              % +MigId, +Record, -Seal
            record_sealed/3             % +MigId, +Record, +Seal
          ]).
:- dynamic apply_macros_was_loaded/0.
:- (   current_module(apply_macros)
   ->  assertz(apply_macros_was_loaded)
   ;   true
   ).
:- use_module(library(sandbox), []).
%   library(sandbox) loads library(apply_macros), whose goal expansion of
%   maplist/N then applies to all code compiled later in the process and
%   changes what it means (a yall lambda's free variables are copied
%   instead of shared). The sandbox needs none of it: unless the process
%   loaded apply_macros itself, its expansion clauses are taken out again.
:- (   apply_macros_was_loaded
   ->  true
   ;   forall(( member(H, [goal_expansion(_, _), goal_expansion(_, _, _, _)]),
                clause(system:H, Body, Ref),
                Body = apply_macros:_ ),
              erase(Ref))
   ).
:- use_module(node, [ctx_node/2, node_property/2]).
:- use_module(agents, [agent_property/3]).
:- use_module(sandbox_check,
              [ check_body/3, with_scratch/3, code_refuse/2, clause_parts/2,
                check_head/1 ]).
:- use_module(program_check, [check_program_text/2]).
:- use_module(sandbox_agent_api, []).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [maplist/2, include/3]).
:- autoload(library(crypto), [crypto_n_random_bytes/2, crypto_data_hash/3]).

/** <module> Mobile code: what arrives over the network runs in a sandbox

Code that a peer sends (an arriving agent's clauses, a program sent
with load_program_at/3 or load_program_text/4) is checked here before
anything of it is installed, with SWI-Prolog's library(sandbox) extended
with the platform's agent API. Locally consulted programs, agents made
on this node and agents sent by a node of this process are trusted.

Rules (a refusal is error(permission_error(install, code, Culprit), _),
Culprit the offending goal, clause head or directive):

  - Every clause body may call only what library(sandbox) deems safe
    (pure computation, lists, arithmetic, strings, format/2 to an atom
    or to current output, assert/retract of *facts* in the agent's own
    module), output to the agent's output (nl/0, print/1, write/1,
    flush_output/0, format/3 to user_output/user_error) and the agent
    API (agent_api/2). Shell, files, halt, foreign calls, op/3, flags,
    qualified asserts (another module), asserted rules and any other
    predicate of a platform module (node, transport, tokens, handlers
    of platform_request) are refused.
  - API calls that name an agent (move, clone, payload, purge) must name
    the agent itself: `guid` in a program, the agent's own name (or the
    first argument of its handler) in an agent's clauses.
  - A goal whose predicate cannot be told (call/1 of a variable) or an
    undefined predicate is refused.
  - An agent's handler must be defined by its own clauses.
  - A program loads into a module of its own (codeload.pl,
    program_module/2) and may define clauses of its own predicates
    there (unqualified heads) and of the hooks declared with
    mobile_hook/1 (an application's hooks), nothing else. Hooks are
    default-deny: no clause or declaration, qualified or not, of a name
    that the Prolog system, a library or the node calls by name
    (hook_refusal/3: SWI-Prolog's hooks called by name, names of
    `system`, of `prolog` and of the node's `user`, names declared
    multifile anywhere, library exports); the refusal's culprit is
    hook(Module:Name/Arity). Its directives may only declare its
    predicates (dynamic, discontiguous, non_terminal), load libraries,
    and name safe initialization goals, which codeload.pl runs after
    the load under the agent bounds.

Side doors. library(sandbox) judges a goal by the predicates it calls;
some goals run without being a visible call in the checked code. Each
family, and what is done about it (sandbox_policy.pl holds the table of
refusals, applied at any depth of the sandbox's walk):

  | family                                | here                        |
  |---------------------------------------|-----------------------------|
  | attribute hooks: put_attr/3, put_attrs/2 (attr_unify_hook, attribute_goals, portray_attvar of the attribute's module run with the value), freeze/when/dif | refused: put_attr(V, freeze, user:shell(C)), V = 1 ran C |
  | attributed variables or cycles in data (records, binary frames) | refused before anyone unifies them (wire.pl for frames, plain_data/1 for programs) |
  | directives of programs                | only declarations of the program's own predicates, libraries of an allow-list (sandbox_policy:safe_library/1), initialization/1 and initialization(G, now) with G checked and run after the load under the agent bounds and a wall clock (codeload.pl; a loop used to spin a connection worker for ever); if/elif, op, flags, include, module, table, encoding refused |
  | quasi quotations                      | refused: their parsers run when the text is read |
  | print_message/2, message_to_string/2, message translation | refused: a format(F, A) message with ~@ calls a goal, and message hooks are the node's |
  | format/1,2,3                          | ~@ arguments checked by the sandbox; ~W refused (its options may hold portray_goal(G)); output only to atoms/strings, current output, user_output, user_error |
  | portray, print                        | print/1 and ~p call the node's portray/1 hook, which a peer cannot define (hooks are refused by name) |
  | hooks the system calls by name, declared or not (prolog_exception_hook/4 is not declared in 9.0.4: with `repeat, fail` it spun a worker at every malformed frame of an unauthenticated peer), exception/3, thread_message_hook/3, prolog_trace_interception/4, prolog_event_hook/1, portray_attvar/1, prolog_predicate_name/2, prolog:message//1, ... | refused by name, in the program's module or qualified (hook_refusal/3); on_signal/3 and at_halt/1 are not in the sandbox |
  | goal and term expansion               | a program may not define expansion hooks (they would run in its module while it loads, after the check); the node's own expand the checked terms |
  | names in `user`                       | programs sent by peers load into modules of their own: the first program to define a name no longer owns it for every other peer's program |
  | flags: set_prolog_flag/2, create_prolog_flag/3, set_prolog_stack/2 | refused: flags are the process's (double_quotes broke every later program load) |
  | reading flags                         | only arithmetic and syntax flags (argv, os_argv, executable, home are refused: argv held tokens) |
  | environment: getenv/2, setenv/2       | refused (the sandbox has neither) |
  | global variables (b_/nb_getval, b_/nb_setval, nb_current) | refused: agents run in the platform's pooled threads |
  | flag/3, recorded database, char_conversion/2, op/3, style_check/1 | refused: tables of the whole process |
  | tabling                               | refused: tables outlive the call |
  | loading code at run time (use_module, load_files, consult) | refused |
  | setup_call_cleanup/3, call_cleanup/2,3, setup_call_catcher_cleanup/4 | refused: a cleanup runs after the platform stopped the agent |
  | catch/3 with a catcher that could be the platform's stop ('$aborted', '$dfrl_purged', '$dfrl_bound'(_), time_limit_exceeded, a variable) | refused, and throwing one of them too: an agent over a bound must stop |
  | abort/0                               | refused: it unwinds the platform's worker |
  | clause/2 of a variable                | refused                     |
  | other agents                          | agent_property/3 of another agent gives only handler, kind, status, hops; modules of other agents cannot be called (not exported) |
  | error terms (thrown by an agent, sent by a peer in a reply) | printed only if inert (platform_errors:inert_error/2); a `~` in any text makes them foreign_error(Text) |

A node trusts peers by name with the node option trusted_peers(Names):
code from a peer whose TLS certificate names one of them is installed
unchecked (node:ctx_peer_name/2; a plaintext peer is never trusted by
name).

The parts: sandbox_check.pl (a body through the sandbox, the scratch
module), program_check.pl (programs), code_hooks.pl (hooks are
default-deny), sandbox_agent_api.pl (the agent API as safe),
sandbox_policy.pl (the refusals at any depth). An application that runs
on the platform declares its own mobile hooks and agent API with the
multifile hooks below, in a file of its own.
*/

:- multifile
    mobile_hook/1,              % ?Module:Name/Arity
    moved_hook/2,               % ?Old, ?New: Module:Name/Arity
    agent_api/2.                % +Module:Goal, -Condition

:- dynamic process_key/1.
:- dynamic checked_code/1.              % Sha: code accepted since the last load

%!  mobile_hook(?PI) is nondet.
%
%   Multifile: Module:Name/Arity is a hook that programs sent by peers
%   may add clauses to (their bodies are checked as any other). E.g.
%
%   ```
%   code_safety:mobile_hook(my_module:my_hook/2).
%   ```

%!  moved_hook(?Old, ?New) is nondet.
%
%   Multifile: the hook Old (Module:Name/Arity) is now New. A program
%   that defines, declares or calls Old is refused with the culprit
%   moved_hook(Old, New), which names the new predicate: the culprit
%   (unlike the context) reaches the node that sent the program, so its
%   message points there too. E.g.
%
%   ```
%   code_safety:moved_hook(my_app:my_hook/2, my_hooks:my_hook/2).
%   ```

%!  agent_api(?Module:Goal, -Condition) is nondet.
%
%   Multifile: Module:Goal, a predicate of a platform module (a module
%   loaded from platform_pl/ or pybridge/), may be called by sandboxed
%   code if Condition (called at check time) succeeds. self(A) means: A
%   is the agent itself. The platform's own entries are in
%   sandbox_agent_api.pl. E.g.
%
%   ```
%   code_safety:agent_api(my_app:my_api(A, _), self(A)).
%   ```

		 /*******************************
		 *            TRUST		*
		 *******************************/

%!  code_trusted(+Ctx) is semidet.
%
%   True if the peer of connection Ctx is trusted by name: the node has
%   the option trusted_peers(Names) and the peer's TLS certificate names
%   one of them.

code_trusted(Ctx) :-
    ctx_node(Ctx, Node),
    catch(node:ctx_peer_name(Ctx, Name), error(existence_error(_, _), _), fail),
    peer_trusted(Node, Name).

%!  peer_trusted(+Node, +PeerName) is semidet.
%
%   True if Node's option trusted_peers(Names) names PeerName.

peer_trusted(Node, Name) :-
    node_property(Node, option(trusted_peers(Names))),
    is_list(Names),
    atom_string(Name, S),
    member(N, Names),
    atom_string(N, S),
    !.

%   A record sent by a node of this process is sealed with a key that
%   never leaves the process: its code was trusted (or checked) here.
key(Key) :-
    (   process_key(Key)
    ->  true
    ;   with_mutex(code_safety_key,
                   (   process_key(Key)
                   ->  true
                   ;   crypto_n_random_bytes(32, Bytes),
                       atom_codes(Key, Bytes),
                       assertz(process_key(Key))
                   ))
    ).

%!  record_seal(+MigId, +Record, -Seal) is det.
%
%   Seal is an HMAC, with this process's key, of migration MigId and
%   Record (as sent): record_sealed/3 accepts it in this process only.

record_seal(MigId, Record, Seal) :-
    key(Key),
    variant_sha1(MigId-Record, Sha),
    crypto_data_hash(Sha, Seal, [algorithm(sha256), hmac(Key)]).

%!  record_sealed(+MigId, +Record, +Seal) is semidet.

record_sealed(MigId, Record, Seal) :-
    atom(Seal),
    catch(record_seal(MigId, Record, Seal0), _, fail),
    Seal0 == Seal.

		 /*******************************
		 *        AGENT RECORDS		*
		 *******************************/

%!  check_agent_record(+Record) is det.
%
%   Check the code of an agent record that arrived from a peer (see the
%   module comment).
%
%   @error permission_error(install, code, Culprit)

check_agent_record(Record) :-
    (   Record = agent(Name0, Handler, _, _, _, Preds, Clauses, _),
        is_list(Preds), is_list(Clauses)
    ->  true
    ;   throw(error(type_error(agent_record, Record), _))
    ),
    (   Name0 = rename(Self, _) -> true ; Self = Name0 ),
    maplist(clause_parts, Clauses, Parts),
    maplist(check_head, Parts),
    (   member(H-_, Parts), callable(H), functor(H, Handler, A), A >= 3
    ->  true
    ;   code_refuse(handler(Handler), 'the handler is not defined by the agent''s own clauses')
    ),
    include(is_rule, Parts, Rules),
    variant_sha1(Self-Handler-Preds-Rules, Key),
    (   Rules == []
    ->  true
    ;   checked_code(Key)
    ->  true
    ;   with_scratch(Preds, Rules,
                     [S]>>forall(member(R, Rules),
                                 check_rule(S, Self, Handler, R))),
        remember_checked(Key)
    ).

%   The code of a record (its rules: the facts are data and are not
%   walked, nor is a payload of 100,000 floats) is checked once; its
%   hash is kept until a program is loaded (which may define what a
%   refused agent lacked, or redefine nothing: programs may not redefine
%   the node's predicates) and at most 512 of them.
remember_checked(Key) :-
    with_mutex(code_safety_cache,
               (   predicate_property(checked_code(_), number_of_clauses(N)),
                   N >= 512
               ->  retractall(checked_code(_)),
                   assertz(checked_code(Key))
               ;   assertz(checked_code(Key))
               )).

%!  forget_checked_code is det.
%
%   Forget which agent code was accepted: called after code is loaded
%   into the node (codeload.pl), which changes what the sandbox sees.

forget_checked_code :-
    retractall(checked_code(_)).

is_rule(_-B) :- B \== true.

%   A handler clause is called by the platform with the agent's own name
%   first (agent_execute/4, a post): its first argument is the agent.
check_rule(S, Self, Handler, H0-B0) :-
    copy_term(H0-B0, H-B),
    (   functor(H, Handler, A), A >= 3, arg(1, H, Me), var(Me)
    ->  Me = Self
    ;   true
    ),
    check_body(S, Self, B).

		 /*******************************
		 *            POSTS		*
		 *******************************/

%!  check_post(+Node, +Agent, +Goal) is det.
%
%   Goal, Handler(Agent, Link, Args...), is an event that Agent on Node
%   declares: one of the list of its fact '$agent_events'(List) (the
%   agent_create/4 option events(List)), or without it, an arity of its
%   handler that the agent's own module defines (Tartarus programs post
%   to their handler's clauses).
%
%   @error permission_error(post, event, Handler/Arity)

check_post(Node, Agent, Goal) :-
    functor(Goal, Handler, Arity),
    agent_property(Node, Agent, module(M)),
    (   catch(M:'$agent_events'(Events), _, fail)
    ->  memberchk(Handler/Arity, Events)
    ;   Arity >= 3,
        functor(H, Handler, Arity),
        current_predicate(M:Handler/Arity),
        \+ predicate_property(M:H, imported_from(_))
    ),
    !.
check_post(_, _, Goal) :-
    functor(Goal, Handler, Arity),
    throw(error(permission_error(post, event, Handler/Arity),
                context(check_post/3, 'not an event this agent declares'))).

