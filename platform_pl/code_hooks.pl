:- module(code_hooks,
          [ hook_refusal/3,             % +Name/Arity, -Module, -Why
            called_by_name/1,           % ?Module:Name/Arity
            qualified_hook/4,           % +Module, +Name/Arity, -Q, -Why
            own_predicate/1             % +Name/Arity
          ]).
:- use_module(sandbox_check, [code_refuse/2, scratch_module/1]).
:- autoload(library(lists), [member/2]).

/** <module> Hooks are default-deny for code from peers

Which names a program sent by a peer may not define, in its own module
or qualified, because the Prolog system, a library or the node calls a
predicate of that name (code_safety.pl's rules; hook_refusal/3 says how
a name is judged).
*/

%!  hook_refusal(+Name/Arity, -Module, -Why) is semidet.
%
%   A program sent by a peer may not define Name/Arity, in its own
%   module or elsewhere (but for the mobile hooks), because the Prolog
%   system, a library or the node calls a predicate of that name (in
%   Module): SWI-Prolog looks several hooks up in `user` whether or not
%   they are declared (user:prolog_exception_hook/4 is not, in 9.0.4),
%   expansion hooks run in the module being loaded, and attribute hooks
%   in the module named by the attribute. Rather than a list alone, a
%   name is refused if
%
%     - it is one of the hooks that SWI-Prolog 9.0.4 calls by name
%       (called_by_name/1: its manual, its C core, and every
%       user:/prolog: hook its library and boot files declare, which
%       tests/platform/test_codeload.pl derives again from the
%       installed sources);
%     - `system` defines it (built-ins, system hooks such as
%       term_expansion/2);
%     - `prolog` or `user` defines or declares it (the node's own
%       predicates; programs sent by peers never load into `user`);
%     - any module of the process declares it multifile (a hook by
%       definition: sandbox:safe_primitive/1, node:platform_request/4);
%     - a library exports it (the autoload index, or a loaded library
%       module).

hook_refusal(F/A, Q, Why) :-
    atom(F), integer(A),
    functor(H, F, A),
    hook_refusal_(F/A, H, Q, Why),
    !.

hook_refusal_(F/A, _, Q, 'a hook the Prolog system or a library calls by name') :-
    called_by_name(Q:F/A).
hook_refusal_(F/A, _, system, 'a predicate of the Prolog system') :-
    current_predicate(system:F/A).
hook_refusal_(F/A, _, Q, 'a predicate or hook the node defines') :-
    member(Q, [user, prolog]),
    current_predicate(Q:F/A).                   % also declared dynamic or multifile
hook_refusal_(_, H, Q, 'a hook (declared multifile there)') :-
    current_predicate(_, Q:H),
    \+ program_or_agent_module(Q),
    predicate_property(Q:H, multifile).
hook_refusal_(F/A, _, Q, 'a predicate of a library') :-
    '$in_library'(F, A, Path),
    file_base_name(Path, Q).
hook_refusal_(_, H, Q, 'a predicate of a library') :-
    current_predicate(_, Q:H),
    module_property(Q, class(Class)),
    memberchk(Class, [library, system]),
    predicate_property(Q:H, exported).

%   (current_predicate/1,2 come first: predicate_property/2 of a name
%   that is not defined autoloads its library, and a program could make
%   the node load any library by naming it.)

program_or_agent_module(M) :-
    (   sub_atom(M, 0, _, _, 'dfrl_program://')
    ;   sub_atom(M, 0, _, _, 'dfrl_agent@')
    ;   scratch_module(M)
    ),
    !.

%!  qualified_hook(+Module, +PI, -Q, -Why) is semidet.
%
%   A clause or declaration for
%   Module:PI would define a hook: Module is user, prolog or system, or
%   declares PI multifile, or the system calls PI by name.
qualified_hook(M, F/A, Q, Why) :-
    hook_refusal(F/A, Q, Why),
    (   memberchk(M, [user, prolog, system])
    ->  true
    ;   called_by_name(_:F/A)
    ->  true
    ;   atom(M),
        current_module(M),                      % makes no module, loads nothing
        current_predicate(M:F/A),
        functor(H, F, A),
        predicate_property(M:H, multifile)
    ),
    !.

%!  own_predicate(+PI) is det.
%
%   A program's own predicate: one that nothing calls by name.
%
%   @error permission_error(install, code, hook(Q:PI)) if something does.

own_predicate(PI) :-
    (   hook_refusal(PI, Q, Why)
    ->  code_refuse(hook(Q:PI), Why)
    ;   true
    ).

%!  called_by_name(?Module:Name/Arity) is nondet.
%
%   Hooks SWI-Prolog 9.0.4 calls by name (non-terminals Name//N are
%   given as Name/N+2). From its manual and C core: the exception,
%   trace, event, signal and undefined-procedure hooks, expansion,
%   portray, attribute hooks (called in the module named by the
%   attribute); then every user:Name/Arity and prolog:Name/Arity its
%   boot/ and library/ sources declare or call (grep of
%   `(user|prolog):Name/Arity` and `//Arity`; the test derives it again).

called_by_name(user:F/A) :- user_hook(F/A).
called_by_name(prolog:F/A) :- prolog_hook(F/A).
called_by_name(system:F/A) :- system_hook(F/A).
called_by_name(attribute:F/A) :- attribute_hook(F/A).

%   Looked up in user (boot/, library/, the C core).
user_hook(prolog_exception_hook/4).
user_hook(exception/3).
user_hook(message_hook/3).
user_hook(thread_message_hook/3).
user_hook(portray/1).
user_hook(portray_message/2).
user_hook(message_property/2).
user_hook(prolog_load_file/2).
user_hook(term_expansion/2).
user_hook(term_expansion/4).
user_hook(term_expansion/6).
user_hook(goal_expansion/2).
user_hook(goal_expansion/4).
user_hook(prolog_trace_interception/4).
user_hook(prolog_event_hook/1).
user_hook(prolog_predicate_name/2).
user_hook(prolog_clause_name/2).
user_hook(prolog_list_goal/1).
user_hook(prolog_stack_frame_property/2).
user_hook(resource/2).
user_hook(resource/3).
user_hook(file_search_path/2).
user_hook(library_directory/1).
user_hook(prolog_file_type/2).
user_hook(expand_query/4).
user_hook(expand_answer/2).
user_hook(url_path/2).
user_hook(generate_message_hook/3).
user_hook(portray_attvar/1).
user_hook(exception_hook/4).
user_hook(prolog_on_signal/2).
user_hook(prolog_alert_signal/2).
user_hook(message_prefix_hook/2).
user_hook(prolog_edit/1).
user_hook(prolog_stack_property/2).

%   Looked up in prolog (boot/, library/).
prolog_hook(prolog_exception_hook/5).
prolog_hook(alternate_syntax/4).
prolog_hook(assertion_failed/2).
prolog_hook(break_hook/7).
prolog_hook(build_config/5).
prolog_hook(build_environment/2).
prolog_hook(build_file/2).
prolog_hook(build_step/4).
prolog_hook(called_by/2).
prolog_hook(called_by/4).
prolog_hook(comment_hook/3).
prolog_hook(complete_input/4).
prolog_hook(confirm/2).
prolog_hook(console_color/2).
prolog_hook(debug_control_hook/1).
prolog_hook(debug_print_hook/3).
prolog_hook(deprecated/3).
prolog_hook(deprecated/4).
prolog_hook(doc_autolink_extension/2).
prolog_hook(doc_canonical_object/2).
prolog_hook(doc_category/3).
prolog_hook(doc_directory/1).
prolog_hook(doc_file_index_header/4).
prolog_hook(doc_file_title/5).
prolog_hook(doc_is_public_object/1).
prolog_hook(doc_links/4).
prolog_hook(doc_nav_tree/4).
prolog_hook(doc_object_footer/4).
prolog_hook(doc_object_href/2).
prolog_hook(doc_object_link/4).
prolog_hook(doc_object_page/4).
prolog_hook(doc_object_page_footer/4).
prolog_hook(doc_object_summary/4).
prolog_hook(doc_object_title/2).
prolog_hook(doc_page_header/4).
prolog_hook(doc_places_menu/3).
prolog_hook(doc_search_field/3).
prolog_hook(doc_url_expansion/3).
prolog_hook(doc_wiki_face/4).
prolog_hook(error_message/3).
prolog_hook(error_message/4).
prolog_hook(general_exception/2).
prolog_hook(generated_predicate/1).
prolog_hook(gpp_options/1).
prolog_hook(heartbeat/0).
prolog_hook(help_hook/1).
prolog_hook(history/2).
prolog_hook(history_line/2).
prolog_hook(hook/1).
prolog_hook(initialize_now/2).
prolog_hook(locate_clauses/2).
prolog_hook(make_hook/2).
prolog_hook(message/3).
prolog_hook(message/4).
prolog_hook(message_context/3).
prolog_hook(message_context/4).
prolog_hook(message_line_element/2).
prolog_hook(message_location/3).
prolog_hook(message_location/4).
prolog_hook(message_prefix_hook/2).
prolog_hook(meta_goal/2).
prolog_hook(no_autoload_module/1).
prolog_hook(obfuscate_identifiers/1).
prolog_hook(open_source_hook/3).
prolog_hook(portray/1).
prolog_hook(predicate_summary/2).
prolog_hook(quasi_quotation_syntax/2).
prolog_hook(rename_predicate/2).
prolog_hook(residual_goals/2).
prolog_hook(runtime_config/2).
prolog_hook(sandbox_allowed_clause/1).
prolog_hook(sandbox_allowed_directive/1).
prolog_hook(sandbox_allowed_expansion/1).
prolog_hook(sandbox_allowed_goal/1).
prolog_hook(show_profile_hook/1).
prolog_hook(show_profile_hook/2).
prolog_hook(theme/1).
prolog_hook(translate_bindings/5).
prolog_hook(translate_message/3).
prolog_hook(tripwire/2).
prolog_hook(url_expansion_hook/3).
prolog_hook(version_msg/1).
prolog_hook(xref_close_source/2).
prolog_hook(xref_open_source/2).
prolog_hook(xref_source_directory/2).
prolog_hook(xref_source_file/3).
prolog_hook(xref_source_identifier/2).
prolog_hook(xref_source_time/2).
prolog_hook(xref_update_syntax/2).

%   Looked up in system (expansion of every module's code).
system_hook(term_expansion/2).
system_hook(term_expansion/4).
system_hook(goal_expansion/2).
system_hook(goal_expansion/4).

%   Called as Attribute:Hook(...) when a variable with that attribute is
%   unified, copied or printed.
attribute_hook(attr_unify_hook/2).
attribute_hook(attribute_goals/3).
attribute_hook(attr_portray_hook/2).
attribute_hook(project_attributes/2).
